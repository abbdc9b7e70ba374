"""Firmware emulator of the RoboMaster C-board that drives a 3-cable SpiRob.

A declared task table run at fixed rates (control at 1 kHz), RC input from DBUS, an explicit failsafe
phase machine, the cable mapping and motor model, the grasp strategy, and the motor bus back ends.
Never imports MuJoCo, viser or pymavlink: the plant is reached only through :class:`MotorBus`.
"""
