"""Tasks of ``gcpfree block``: a block of overlapping scenes oriented in one adjustment
(:func:`core.orientation.adjust.adjust`). The tie points of every overlapping image and their
joint relative orientation are :func:`flows.relative.views_relative_flow`'s; here each stereo
pair's relative DEM and surface-matching GCPs (:mod:`tasks.block.pairs`), the tracks as the
adjustment's tie points (:mod:`tasks.block.ties`), and the block's products: RPC exports,
report.json (:mod:`tasks.block.products`)."""
