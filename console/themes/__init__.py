"""Theme files (YAML) and the theme variables the CSS uses."""
