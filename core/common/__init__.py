"""Machinery every other core package uses: the bounded caches, the blob codec, the parallel runner, least-squares fitting."""
