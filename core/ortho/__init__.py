"""Step 5: orthorectification (:mod:`core.ortho.ortho`), its compiled kernels
(:mod:`core.ortho.kernels`) and the comparison of two orthos (:mod:`core.ortho.ortho_compare`)."""
