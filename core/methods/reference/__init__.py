"""REFERENCE (Inger et al. 2013, eq. 1): the pixel-basis triple product over every cubemap texel."""
