"""Shared test helpers: fake boards and peers, rigs, browser and MAVProxy processes, guards."""
