"""Image matching kernels: tie points (step 1 of the chain), later dense matching (step 2)."""
