"""What the console's commands share (console, demo, review, web): defaults and the binding ids."""

from __future__ import annotations

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"
THEME_HELP = (
    "theme name: missionctl-dark (default), missionctl-light, missionctl-high-contrast, "
    "missionctl-colorblind, "
    "or one of yours in ~/.config/missionctl/themes/*.yaml (default: the config file's; "
    "a theme picked in the command palette is remembered there)"
)


def known_binding_ids() -> set[str]:
    """Every binding id a user may remap in the config file's [keymap]."""
    from console.state.actions import ACTIONS, REVIEW_ACTIONS

    return {a.binding_id for a in [*ACTIONS, *REVIEW_ACTIONS] if not a.fixed}
