"""physrelight."""
