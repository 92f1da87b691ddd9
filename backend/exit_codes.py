"""The exit codes of every `missionctl` command (the CLI contract in the README)."""

EXIT_OK = 0  # done
EXIT_REFUSED = 1  # the server (or a robot) refused the operation
EXIT_BAD_INPUT = 2  # bad input or usage: a file, a parameter, an option
EXIT_UNREACHABLE = 3  # the server could not be reached, or the login was refused
EXIT_OVERDUE = 4  # `ctl wait`: the stage waited for is overdue (or no due, and time ran out)
