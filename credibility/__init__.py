"""Simulation-credibility indices of Dai et al. computed from logs, with plots and reports."""
