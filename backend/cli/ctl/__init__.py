"""`missionctl ctl`: every mission operation, scriptable against a running server."""
