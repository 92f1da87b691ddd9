"""The console screens and dialogs. They post messages; none imports the app."""
