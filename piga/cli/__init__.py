"""Command-line entry points. Each one only parses its arguments, calls one library function and saves."""
