"""Cycles' reflectance: microfacet distributions, the Lambert/Glossy/Principled materials, their albedo tables, the pixel filter."""
