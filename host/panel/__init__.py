"""The teleop panel: the guarded viser server, its sections, the control arbiter, the board's state."""
