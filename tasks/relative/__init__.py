"""Step 1: tie points and the relative orientation of a pair."""
