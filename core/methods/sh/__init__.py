"""SH (Sloan, Kautz, Snyder 2002): diffuse transfer in spherical harmonics."""
