"""The board link on the host's side: the link process that owns the port, its client, sources, replay."""
