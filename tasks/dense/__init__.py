"""Step 2: dense matching, tile by tile, into a DEM."""
