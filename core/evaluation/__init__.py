"""Step 6: accuracy against lidar (:mod:`core.evaluation.evaluation`, the eval.json document
:mod:`core.evaluation.evaluation_report`), DEM coregistration (:mod:`core.evaluation.coregister`)
and SRTM void filling (:mod:`core.evaluation.void_fill`)."""
