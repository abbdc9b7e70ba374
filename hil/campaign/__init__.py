"""Campaigns: grids or samples of grasp trials and scenarios, on local processes or Ray (docs/campaigns.md)."""
