"""Many pairs: the catalog, the summary and the STAC catalogs."""
