"""fractalc: a compiler for 3D fractal scenes (.frac -> OpenCL -> EXR/PNG)."""
__version__ = "0.1.0"

from .errors import RenderError, SceneError  # noqa: E402
from .api import Camera, Image, Scene, load, loads  # noqa: E402

__all__ = ["load", "loads", "Scene", "Image", "Camera", "SceneError", "RenderError", "__version__"]
