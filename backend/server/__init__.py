"""The mission server: Zenoh router, rules, journal, robot link, accounts and access control."""
