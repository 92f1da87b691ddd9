"""`missionctl review`: the console, read-only, at any instant of a recorded mission."""
