"""Functions on the sphere: cubemap directions and texel solid angles, the World's environment and its exact resampling, the compact sources split off it."""
