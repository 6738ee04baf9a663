"""Result codes, input checks and device helpers every layer uses."""
