"""Type stubs of the native module; the package's own API is in __init__.py (typed inline)."""

import os
from typing import Any, Callable, Dict, List, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, "os.PathLike[str]"]
_Progress = Optional[Callable[[str, int, int, str, bool], None]]

class MatfitError(Exception): ...
class SceneError(MatfitError): ...
class PhotoError(MatfitError): ...
class RecoverError(MatfitError): ...
class ExportError(MatfitError): ...
class OptionsError(MatfitError): ...

class Scene:
    @staticmethod
    def load(path: _Path) -> "Scene": ...
    @property
    def path(self) -> str: ...
    @property
    def groups(self) -> List[str]: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    def render(
        self,
        spp: Optional[int] = None,
        seed: Optional[int] = None,
        aov: str = "beauty",
        view: Optional[str] = None,
        progress: _Progress = None,
    ) -> npt.NDArray[Any]: ...
    def edit(
        self,
        *,
        edit_files: Sequence[_Path] = ...,
        remove: Sequence[str] = ...,
        moves: Sequence[str] = ...,
        scale_light: Sequence[str] = ...,
        material: Sequence[str] = ...,
        add: Sequence[str] = ...,
        look_from: Optional[Sequence[float]] = None,
        look_at: Optional[Sequence[float]] = None,
        fov: Optional[float] = None,
    ) -> "Scene": ...

def recover(
    scene: Scene,
    photos: Sequence[Union[str, npt.NDArray[np.float32]]],
    options: Dict[str, Any],
    progress: _Progress = None,
) -> Dict[str, Any]: ...
def composite(
    scene: Scene,
    photo: Union[str, npt.NDArray[np.float32]],
    *,
    edit_files: Sequence[_Path] = ...,
    remove: Sequence[str] = ...,
    moves: Sequence[str] = ...,
    scale_light: Sequence[str] = ...,
    material: Sequence[str] = ...,
    add: Sequence[str] = ...,
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    exposure: Optional[float] = None,
    response: str = "srgb",
    progress: _Progress = None,
) -> npt.NDArray[np.float32]: ...
def read_image(path: _Path) -> npt.NDArray[np.float32]: ...
