"""WAVELET (Ng, Ramamoorthi, Hanrahan 2003/2004): Haar transform on cube faces, non-linear lighting approximation, triple products."""
