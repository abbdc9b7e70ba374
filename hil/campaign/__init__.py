"""Campaigns: grids or samples of grasp trials and scenarios, on processes or on Ray (docs/campaigns.md)."""
