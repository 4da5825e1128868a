"""Steps 3-4: surface matching of the relative DEM to the reference (simulated GCPs) and the absolute orientation."""
