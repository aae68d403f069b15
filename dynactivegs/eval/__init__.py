"""Evaluation: metrics, held-out views, benchmark tables and plots."""
