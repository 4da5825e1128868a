"""Reading and writing: rasters, DEMs and their vertical datum, sensor models, SPOT DIMAP, lidar, CRSs, the geoid, SRTM tiles and the reference made of them."""
