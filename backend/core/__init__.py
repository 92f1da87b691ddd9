"""The mission core: model, skill libraries, events (the one mutator), operations and rules.

pydantic and the standard library only: no Zenoh, no asyncio, no Textual.
"""
