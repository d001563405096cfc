"""Error metrics (the one rel-L2), images and the HTML speed/error report."""
