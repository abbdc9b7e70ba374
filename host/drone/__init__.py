"""The MAVLink drone link: the arm as a gripper component on the drone's network (docs/mavlink.md)."""
