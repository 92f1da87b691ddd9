"""Mission, library and schema files: YAML in and out, every problem located as file:line:col."""
