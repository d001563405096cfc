"""RSL (Xu, Jia, Hu, Tai 2006): rotatable square lights, BRDF SATs, visibility distance tables, clustered PCA."""
