"""Analytic baseline controllers."""
