"""Spherical Gaussians (Wang et al. 2009): the algebra, NDFs as SG lobes, SG BRDFs with the spherical warp, SG lighting."""
