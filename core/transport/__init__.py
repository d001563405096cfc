"""Light that bounces: interreflected transfer (Sloan, Kautz, Snyder 2002) in the form of
direct-to-indirect transfer (Hasan, Pellacini, Bala 2006) -- gather clusters of shading
points, each receiver's row over them from the rays the visibility precompute traces, and
the per-frame bounce from the direct light at the clusters."""
