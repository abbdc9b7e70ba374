"""``spirob-hil``: the command line of the plant and the harness (``hil.cli.main``)."""
