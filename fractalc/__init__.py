"""fractalc: a compiler for 3D fractal scenes (.frac -> OpenCL -> EXR/PNG)."""
from .api import Camera, Image, Scene, load, loads
from .errors import RenderError, SceneError
from .version import __version__

__all__ = ["load", "loads", "Scene", "Image", "Camera", "SceneError", "RenderError", "__version__"]
