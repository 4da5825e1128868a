"""Accuracy studies behind the documentation's validation tables (each writes a results file)."""
