"""BLOCKS (Inger, Farbman, Lischinski 2013): block layout and differential visibility, the glossy lobe, batched Algorithm 1."""
