"""SSDF_SG (Wang et al. 2009): spherical signed distance functions, their PCA, per-point SG shading, the scene's SG lighting."""
