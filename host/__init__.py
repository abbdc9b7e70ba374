"""The host program: `spirob-host`, its browser teleop panel (viser) and the MAVLink drone link."""
