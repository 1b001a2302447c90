"""One module per main view of the window."""
