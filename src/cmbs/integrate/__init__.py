"""Integrators on generic vector fields and residuals (no mechanics imported here)."""
