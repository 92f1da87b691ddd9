"""The plan's future: predictions and plan checks (Textual-free, like the rules).

- `geometry`: points, polygons and paths (stdlib);
- `inputs`: what predictions take besides the mission and the library: the
  time, the robots' last telemetry (`RobotNow`), the link (`LinkModel`) and,
  when one is known, the site map (`SiteMap`, a Protocol implemented outside
  the core, e.g. over the map feed's numpy mirror in backend/client/planning.py);
- `legs`: what one skill does from where it starts (travel, time, energy);
- `course`: each robot's plan walked skill by skill (positions, battery),
  independent of time and of the other robots;
- `order`: barriers across robots: the order they can be passed in, and
  deadlocks;
- `forecast`: predicted start and end of every skill, barrier waits, battery
  and comms coverage along the plan, end per robot and for the mission,
  critical path; `Forecaster` recomputes incrementally;
- `checks`: the plan checks, one small rule each in a table, with stable
  check ids; `gate`: the refusal of a sync with unwaived errors.
"""
