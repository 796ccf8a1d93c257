"""Many pixels at once: per-pixel detection maps over an image cube (time, y, x), the pixels that
carry a vibration, and the scheduler (Dask) that runs this work chunk by chunk."""
