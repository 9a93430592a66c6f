"""fractalc's version: in image metadata, kernel headers and `--version`."""
__version__ = "0.1.0"
