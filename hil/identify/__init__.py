"""Identification: fit the plant's uncertain parameters to recordings of the lab's arm (docs/identify.md)."""
