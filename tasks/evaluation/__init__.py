"""Step 6 and DEM products: lidar evaluation, SRTM void filling, DEM coregistration."""
