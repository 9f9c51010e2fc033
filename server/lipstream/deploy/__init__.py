"""Deployments of the lipstream server beyond ``lipstream serve`` (``ray``: Ray Serve)."""
