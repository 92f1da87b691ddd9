"""The simulator's refusal: a rule of the world said no, in a sentence."""


class SimError(Exception):
    """A rule of the world refused something; the message is a sentence."""
