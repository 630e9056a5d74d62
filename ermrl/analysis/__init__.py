"""Figures, statistics and the HTML report."""
