"""Every operator action in one table: key, footer label, help text, group.

Key bindings (console/bindings.py), the footer, the help screen and the
command palette are all generated from this table, so they cannot disagree;
every key named to a person (hints, status lines, buttons, notifications) is
written from it too, with the user's keymap applied (console/state/keys.py).
Each action has a stable binding id ("<scope>.<name>") that users remap in their config file:

    [keymap]
    "mission.sync" = "S"
    "app.show_fleet" = "f4,3"

The scope says where an action is bound: "mission" (the schedule screen,
action_<name> there), "app" (every screen: switching screens), "editor" (the
parameter editor), "dialog" (the dialogs: each binds the ones it offers), or
one screen ("map", "log", "alerts").
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Action:
    name: str  # action_<name> on the mission screen
    key: str  # default key(s), comma separated
    label: str  # short footer label
    description: str  # help screen / palette
    group: str
    footer: bool = False  # shown in the footer (the rest: help screen and palette)
    scope: str = "mission"
    priority: bool = False  # bound before the focused widget's keys
    bound: bool = True  # bindings(scope) binds it; else where it applies (bindings.bind)
    fixed: bool = False  # a key the widgets handle themselves: not remappable

    @property
    def binding_id(self) -> str:
        # "map.zoom_in" for map_zoom_in: the scope is not repeated
        return f"{self.scope}.{self.name.removeprefix(self.scope + '_')}"

    @property
    def palette_title(self) -> str:
        return f"{SCOPE_TITLES.get(self.scope, self.scope.title())}: {self.label}"

    @property
    def opens(self) -> bool:
        """It opens a dialog, picker, prompt or the editor: keys typed right after
        it are for that (console/typeahead.py)."""
        return self.binding_id in OPENS

    @property
    def to_robot(self) -> bool:
        """It sends a command to a robot: only a press on the schedule itself runs it."""
        return self.binding_id in TO_ROBOT


# actions that open something keys typed next are for, whenever they apply (quit asks
# when something is under way, else the console ends)
OPENS = frozenset(
    {
        "mission.add",
        "mission.edit",
        "mission.cancel",
        "fleet.cancel",
        "fleet.retire",
        "mission.give_to",
        "mission.search",
        "mission.delete",
        "mission.reset",
        "mission.reset_all",
        "mission.save",
        "mission.load",
        "log.export",
        "checks.waive",
        "map.add_marker",
        "map.rename_marker",
        "map.delete_marker",
        "app.help",
        "app.command_palette",
        "app.quit",
        "app.answer",
        "alerts.answer",
    }
)
# actions that send a command up the link to a robot
TO_ROBOT = frozenset(
    {
        "mission.sync",
        "mission.unsync",
        "mission.cancel",
        "mission.retry",
        "mission.run",
        "mission.pause",
        "mission.stop",
        "mission.reset",
        "mission.run_all",
        "mission.pause_all",
        "mission.stop_all",
        "mission.reset_all",
    }
)

SCOPE_TITLES = {
    "mission": "Mission",
    "app": "Screen",
    "editor": "Editor",
    "dialog": "Dialog",
    "map": "Map",
    "log": "Event log",
    "alerts": "Alerts",
    "fleet": "Fleet",
    "timeline": "Timeline",
    "checks": "Plan checks",
    "review": "Review",
}


ACTIONS: list[Action] = [
    # editing the plan
    Action(
        "add",
        "a",
        "Add",
        "Add a skill to the robot's plan after the cursor (picker with fuzzy filter)",
        "Plan",
        True,
    ),
    Action(
        "edit",
        "enter,e",
        "Edit",
        "Edit the selected skill's parameters (below 100 columns: opens the editor beside "
        "the schedule; escape closes it)",
        "Plan",
    ),
    Action(
        "duplicate",
        "c",
        "Duplicate",
        "Duplicate the selected skill: an idle copy after it (or first in the plan)",
        "Plan",
    ),
    Action(
        "search",
        "slash",
        "Find",
        "Find a skill by id, label, skill, robot or parameter and jump to it",
        "Plan",
    ),
    Action(
        "delete", "d,delete", "Delete", "Delete the selected idle skill (asks first)", "Plan", True
    ),
    Action("move_up", "shift+up,K", "Up", "Move the selected idle skill up in the plan", "Plan"),
    Action(
        "move_down", "shift+down,J", "Down", "Move the selected idle skill down in the plan", "Plan"
    ),
    Action("undo", "ctrl+z", "Undo", "Undo your last edit of the plan", "Plan"),
    Action("redo", "ctrl+y", "Redo", "Redo what you undid", "Plan"),
    # synchronization
    Action(
        "sync",
        "s",
        "Sync",
        "Synchronize the robot's plan down to the cursor (send it to the robot)",
        "Synchronization",
        True,
    ),
    Action(
        "unsync",
        "u",
        "Unsync",
        "Take back queued skills from the cursor to the end",
        "Synchronization",
        True,
    ),
    Action(
        "mark",
        "space",
        "Mark",
        "Mark/unmark a skill for a barrier (one per robot)",
        "Synchronization",
    ),
    Action(
        "barrier",
        "b",
        "Barrier",
        "Make a barrier of the marked skills; with none marked, set how long the selected "
        "skill's barrier waits (then start alone or fail)",
        "Synchronization",
        True,
    ),
    Action(
        "unbarrier", "B", "Unbarrier", "Remove the barrier of the selected skill", "Synchronization"
    ),
    Action(
        "give_to",
        "G",
        "Give to…",
        "Give the selected idle skill (or the marked ones, or a retired robot's whole plan) "
        "to another robot that offers it: robots ranked by the forecast's end and battery left",
        "Plan",
    ),
    Action(
        "cancel",
        "w",
        "Cancel cmd",
        "Cancel the pending command that locks the selected skill (⇡), asking first; one "
        "already sent is cancelled unless the robot applied it first (its answer says)",
        "Synchronization",
    ),
    Action(
        "retry",
        "t",
        "Retry",
        "Retry the selected failed skill as it was (new attempt queued right after it)",
        "Synchronization",
    ),
    Action(
        "retry_edit",
        "T",
        "Edit+retry",
        "Retry the selected failed skill after editing it: its next attempt, idle, first in "
        "the plan (edit it, then sync)",
        "Synchronization",
    ),
    # execution
    Action("run", "r", "Run", "Run (or resume) the selected robot", "Execution", True),
    Action("pause", "p", "Pause", "Pause the selected robot", "Execution", True),
    Action(
        "stop",
        "x",
        "Stop",
        "Stop the selected robot's active skill (it returns to the queue)",
        "Execution",
        True,
    ),
    Action(
        "reset",
        "z",
        "Reset",
        "Reset the selected robot: stop and unsynchronize everything queued (asks first)",
        "Execution",
    ),
    Action("run_all", "R", "Run all", "Run (or resume) all robots", "Execution"),
    Action("pause_all", "P", "Pause all", "Pause all robots", "Execution"),
    Action("stop_all", "X", "Stop all", "Stop all robots", "Execution"),
    Action("reset_all", "Z", "Reset all", "Reset all robots (asks first)", "Execution"),
    # mission files and view
    Action("save", "ctrl+s", "Save", "Save the mission to a YAML file", "Mission"),
    Action(
        "load", "ctrl+o", "Load", "Load a mission from a YAML file (replaces the plan)", "Mission"
    ),
    Action(
        "toggle_static", "v", "Static robots", "Expand/collapse the static robots' columns", "View"
    ),
    # screens (app modes)
    Action(
        "show_mission",
        "f2,1",
        "Schedule",
        "Show the schedule (mission screen)",
        "Screens",
        True,
        "app",
    ),
    Action("show_map", "f3,2", "Map", "Show the map of the site", "Screens", True, "app"),
    Action(
        "show_fleet",
        "f4,3",
        "Fleet",
        "Show the fleet: presence, manifests, battery/link history; filter by capability",
        "Screens",
        True,
        "app",
    ),
    Action(
        "show_log",
        "f5,4",
        "Log",
        "Show the event log: operations, reports, refusals, failures, alerts",
        "Screens",
        True,
        "app",
    ),
    Action(
        "show_alerts",
        "f6,5",
        "Alerts",
        "Show the alert list (acknowledge alerts there)",
        "Screens",
        True,
        "app",
    ),
    # screen-specific
    Action(
        "export",
        "ctrl+s",
        "Export",
        "Export the shown event-log entries to a JSON-lines file",
        "Event log",
        True,
        "log",
    ),
    Action(
        "ack", "enter,a", "Acknowledge", "Acknowledge the selected alert", "Alerts", True, "alerts"
    ),
    Action("ack_all", "A", "Ack all", "Acknowledge every alert", "Alerts", True, "alerts"),
    Action(
        "answer",
        "o",
        "Answer",
        "Answer the question of the selected alert (a robot asks)",
        "Alerts",
        False,  # the screen's hint names it: its footer is full at 80 columns
        "alerts",
    ),
    Action(
        "fleet_cancel",
        "delete",  # not a letter: letters typed on the list start the filter
        "Cancel cmd",
        "Cancel one of the selected robot's pending commands (its uplink), asking first",
        "Fleet",
        True,
        "fleet",
    ),
    Action(
        "fleet_add",
        "insert",  # not a letter: letters typed on the list start the filter
        "Add robot",
        "Add the selected robot that asks to join (✚) to the mission",
        "Fleet",
        True,
        "fleet",
    ),
    Action(
        "fleet_retire",
        "ctrl+x",
        "Retire",
        "Retire the selected robot (asks why): no new syncs, its queue taken back, its plan "
        "to give to another robot",
        "Fleet",
        True,
        "fleet",
    ),
    # the map screen
    Action("map_zoom_in", "plus,equals_sign", "Zoom+", "Zoom in", "Map", True, scope="map"),
    Action("map_zoom_out", "minus", "Zoom-", "Zoom out", "Map", True, scope="map"),
    Action("map_fit", "0,home", "Fit", "Zoom out to the whole site", "Map", scope="map"),
    Action("map_pan_left", "shift+left,H", "Pan left", "Pan the view west", "Map", scope="map"),
    Action("map_pan_right", "shift+right,L", "Pan right", "Pan the view east", "Map", scope="map"),
    Action("map_pan_up", "shift+up,K", "Pan up", "Pan the view north", "Map", scope="map"),
    Action("map_pan_down", "shift+down,J", "Pan down", "Pan the view south", "Map", scope="map"),
    Action("map_centre", "c", "Centre", "Centre the view on the cursor", "Map", scope="map"),
    Action(
        "map_follow",
        "f",
        "Follow",
        "Follow a robot (again: the next one; after the last: stop)",
        "Map",
        True,
        scope="map",
    ),
    Action(
        "map_turn_left",
        "left_square_bracket",
        "Turn left",
        "Turn the cursor's heading 15° counter-clockwise",
        "Map",
        scope="map",
    ),
    Action(
        "map_turn_right",
        "right_square_bracket",
        "Turn right",
        "Turn the cursor's heading 15° clockwise",
        "Map",
        scope="map",
    ),
    Action(
        "map_next_marker",
        "n,tab",
        "Next marker",
        "Select the next marker (the cursor jumps to it)",
        "Map",
        scope="map",
    ),
    Action(
        "map_add_marker",
        "a",
        "Add marker",
        "Add a marker (pose, position or area) at the cursor",
        "Map",
        True,
        scope="map",
    ),
    Action(
        "map_move_marker",
        "m",
        "Move marker",
        "Move the selected marker to the cursor (a pose takes the cursor's heading)",
        "Map",
        True,
        scope="map",
    ),
    Action("map_rename_marker", "r", "Rename", "Rename the selected marker", "Map", scope="map"),
    Action(
        "map_delete_marker",
        "d,delete",
        "Delete marker",
        "Delete the selected marker (asks first)",
        "Map",
        scope="map",
    ),
    Action(
        "map_bind",
        "b",
        "Bind",
        "Bind the selected marker to a fitting parameter of the schedule's selected skill "
        "(several fit: choose one)",
        "Map",
        True,
        scope="map",
    ),
    Action(
        "map_pick",
        "p",
        "Pick pose",
        "Set the selected skill's pose/position parameter to the cursor "
        "(position + heading; several: choose one)",
        "Map",
        True,
        scope="map",
    ),
    Action("map_legend", "l", "Legend", "Show/hide the legend", "Map", scope="map"),
    # the plan's timeline and checks (console/screens/timeline.py, checks.py); not in the
    # footers of the other screens, which are full at 80 columns: help and palette list them
    Action(
        "show_timeline",
        "f7,6",
        "Timeline",
        "Show the predicted timeline of the plan: bars per skill, barrier waits, coverage",
        "Screens",
        scope="app",
    ),
    Action(
        "answer",
        "f9",
        "Answer",
        "Answer a robot's question (the oldest open one; the palette lists each, the alerts "
        "screen the one of its alert)",
        "Screens",
        scope="app",
        bound=False,  # the app binds it, out of the footers (full at 80 columns)
    ),
    Action(
        "show_checks",
        "f8,7",
        "Checks",
        "Show the plan checks (energy, coverage, barriers, terrain, parameters); waive there",
        "Screens",
        scope="app",
    ),
    *(
        Action(f"timeline_{name}", key, label, text, "Timeline", footer, "timeline")
        for name, key, label, text, footer in (
            ("prev", "left,h", "◀", "Select the robot's previous skill", False),
            ("next", "right,l", "▶", "Select the robot's next skill", False),
            ("up", "up,k", "Up", "Select a skill of the robot above, at the same time", False),
            (
                "down",
                "down,j",
                "Down",
                "Select a skill of the robot below, at the same time",
                False,
            ),
            ("zoom_in", "plus,equals_sign", "Zoom+", "Zoom in (around the selection)", True),
            ("zoom_out", "minus", "Zoom-", "Zoom out (around the selection)", True),
            ("fit", "0,home", "Fit", "Show the whole mission: what happened, then the plan", True),
            ("now", "n", "Now", "Scroll to now", False),
            ("earlier", "shift+left,less_than_sign", "Earlier", "Scroll back in time", False),
            ("later", "shift+right,greater_than_sign", "Later", "Scroll on in time", False),
            ("schedule", "enter", "Schedule", "Show the selected skill in the schedule", True),
        )
    ),
    Action(
        "checks_waive",
        "w",
        "Waive",
        "Waive the selected finding, with a reason",
        "Checks",
        True,
        "checks",
    ),
    Action(
        "checks_unwaive",
        "u",
        "Unwaive",
        "Withdraw the selected finding's waiver",
        "Checks",
        True,
        "checks",
    ),
    Action(
        "checks_schedule",
        "enter",
        "Schedule",
        "Show the finding's skill in the schedule",
        "Checks",
        True,
        "checks",
    ),  # every screen: help, the palette, quit (bound by the app and the screens that show them)
    Action(
        "help",
        "f1,question_mark",
        "Help",
        "This help screen: every key, the statuses, how to remap keys",
        "App",
        scope="app",
        bound=False,
    ),
    Action(
        "command_palette",
        "ctrl+p",
        "All keys",
        "Command palette: every action, searchable, and why it does not apply now",
        "App",
        scope="app",
        priority=True,
        bound=False,
    ),
    Action(
        "focus",
        "tab",
        "Focus",
        "Move between the schedule and the parameter editor (and between fields)",
        "App",
        scope="app",
        bound=False,
        fixed=True,
    ),
    Action(
        "back",
        "escape",
        "Back",
        "Back to the schedule; close a dialog; leave a filter field",
        "App",
        scope="app",
        bound=False,
        fixed=True,
    ),
    Action(
        "quit",
        "ctrl+q",
        "Quit",
        "Quit (asks first while robots execute, commands wait or the plan is unsaved)",
        "App",
        scope="app",
        priority=True,
        bound=False,
    ),
    # the parameter editor (console/widgets/editor/editor.py)
    *(
        Action(name, key, label, text, "Parameter editor", scope="editor")
        for name, key, label, text in (
            ("apply", "enter", "Apply", "Apply the edited parameters (from any field)"),
            ("revert", "ctrl+r", "Revert", "Discard your changes to the skill"),
            ("leave", "escape", "Close", "Back to the schedule (below 100 columns: closes it)"),
            ("select_all", "ctrl+a", "Select all", "Select all of a text box (a polygon's points)"),
        )
    ),
    # dialogs (console/screens/dialogs.py): each binds those it offers
    *(
        Action(name, key, label, text, "Dialogs", scope="dialog", priority=prio, bound=False)
        for name, key, label, text, prio in (
            ("ok", "enter", "OK", "Accept: the typed text, the highlighted entry", False),
            ("cancel", "escape", "Cancel", "Close the dialog; nothing is done", False),
            ("yes", "y", "Yes", "Answer yes (the question says what it does)", False),
            ("no", "n", "No", "Answer no: nothing is done", False),
            ("next", "down", "Next", "The next entry of the list", False),
            ("previous", "up", "Previous", "The previous entry of the list", False),
            ("complete", "tab", "Complete", "Complete the typed file path", True),
            ("save_first", "s", "Save first", "Quitting: save the mission, then quit", False),
            ("quit", "q,y,ctrl+q", "Quit", "Quitting: quit now", True),
            ("retry", "r", "Retry", "The server is unreachable: try again", True),
            (
                "choose",
                "1,2,3,4,5,6,7,8,9",
                "Choose",
                "A robot's question: answer with the choice of that number",
                True,
            ),
        )
    ),
]

# `missionctl review` (console/review/app.py) only: bound on its app, so on every
# screen; its help, palette and footer add them to the rest
REVIEW_ACTIONS: list[Action] = [
    Action(f"review_{name}", key, label, text, "Review", True, "review")
    for name, key, label, text in (
        ("next", "full_stop", "Next", "Step to the next change (operation, report, alert)"),
        ("prev", "comma", "Prev", "Step back to the previous change"),
        ("goto", "g", "Go to", "Go to a time (14:32, 14:32:05, +10m, -30s) or a revision (#120)"),
        ("play", "o", "Play", "Play from here at the chosen speed, or pause"),
        ("faster", "right_curly_bracket", "Faster", "Play faster"),
        ("slower", "left_curly_bracket", "Slower", "Play slower"),
        (
            "clock",
            "C",
            "Clock",
            "Switch between ground time (what the ground knew at T) and robot time "
            "(what the robots reported happened at T)",
        ),
    )
]

BY_ID = {a.binding_id: a for a in [*ACTIONS, *REVIEW_ACTIONS]}

# the mission screen's actions (the rest are bound elsewhere)
BY_NAME = {a.name: a for a in ACTIONS if a.scope == "mission"}

# actions that need a skill/robot under the cursor and apply to the server
MUTATING = set(BY_NAME) - {"edit", "save", "toggle_static", "mark", "search"}


NAV_KEYS: list[tuple[str, str, str]] = [
    ("arrows", "Map cursor", "On the map: move the cursor (ctrl+arrows: 8 cells)"),
    ("↑ ↓", "Skill", "Previous / next skill in the robot's column"),
    ("← →", "Robot", "Previous / next robot column"),
    ("home end", "Ends", "First / last skill of the column"),
    ("pgup pgdn", "Page", "Scroll a page"),
]

EDITOR_NOTES: list[tuple[str, str, str]] = [
    ("30 / 30deg / 0.5rad", "Angles", "Angles are typed in degrees (heading 0° east, ccw)"),
]
