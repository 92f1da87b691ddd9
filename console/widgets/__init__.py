"""Widgets the screens are built from. They post messages; none imports the app."""
