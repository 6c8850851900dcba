"""matfit: recover the materials of a real scene from one photograph by inverse global
illumination. A thin layer over the Rust library's front door (``matfit::recover``,
``matfit::render``, ...): the same calls as the ``matfit`` command line, the same numbers.

    >>> import matfit
    >>> scene = matfit.Scene.load("scenes/figure6/scene.toml")
    >>> photo = scene.render(spp=64)                      # float32 (H, W, 3)
    >>> rec = matfit.recover(scene, [photo], max_iterations=4)
    >>> rec.groups["floor"].level, rec.groups["floor"].parameters["rho_d"]
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _matfit
from ._matfit import (
    ExportError,
    MatfitError,
    OptionsError,
    PhotoError,
    RecoverError,
    SceneError,
)

__all__ = [
    "Scene",
    "Recovery",
    "GroupResult",
    "recover",
    "composite",
    "read_image",
    "MatfitError",
    "SceneError",
    "PhotoError",
    "RecoverError",
    "ExportError",
    "OptionsError",
]


def _interactive() -> bool:
    """A progress bar only where someone watches: a notebook, or a terminal on stderr."""
    if os.environ.get("MATFIT_PROGRESS") == "0":
        return False
    try:
        from IPython import get_ipython  # type: ignore

        shell = get_ipython()
        if shell is not None and type(shell).__name__ == "ZMQInteractiveShell":
            return True
    except Exception:
        pass
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


class _TextBar:
    """tqdm's calls, drawn as one line on stderr rewritten in place (a terminal and a
    notebook both honour the carriage return): the bar when tqdm is not installed."""

    def __init__(self, total: int, desc: str, leave: bool = False) -> None:
        self.total, self.n, self.desc = max(total, 1), 0, desc
        self.start = time.monotonic()

    def set_description(self, desc: str, refresh: bool = True) -> None:
        self.desc = desc

    def refresh(self) -> None:
        frac = min(self.n / self.total, 1.0)
        filled = int(frac * 30)
        elapsed = time.monotonic() - self.start
        line = f"{self.desc[:40]:<40} [{'#' * filled}{'.' * (30 - filled)}] {frac:4.0%} {elapsed:5.0f} s"
        sys.stderr.write("\r" + line)
        sys.stderr.flush()

    def close(self) -> None:
        sys.stderr.write("\r" + " " * 90 + "\r")
        sys.stderr.flush()


class _Progress:
    """The Rust side's progress as tqdm bars (tqdm.auto: a widget in notebooks, text in a
    terminal), or as a line of text when tqdm is not installed; nothing when no one watches."""

    def __init__(self) -> None:
        self.bar = None
        self.task = None
        try:
            from tqdm.auto import tqdm  # type: ignore

            self.tqdm = tqdm
        except Exception:
            self.tqdm = _TextBar

    def __call__(self, task: str, done: int, total: int, message: str, finished: bool) -> None:
        if self.bar is not None and (task != self.task or finished):
            self.bar.n = self.bar.total if finished else self.bar.n
            self.bar.close()
            self.bar = None
        if finished:
            return
        if self.bar is None:
            self.bar = self.tqdm(total=total, desc=task, leave=False)
            self.task = task
        self.bar.n = done
        if message:
            self.bar.set_description(message, refresh=False)
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _progress(progress: Optional[bool]):
    show = _interactive() if progress is None else progress
    return _Progress() if show else None


def _close(p) -> None:
    if p is not None:
        p.close()


class Scene:
    """A scene file loaded: camera, objects in groups, lights (docs/USAGE.md, "Scene files")."""

    def __init__(self, inner: "_matfit.Scene") -> None:
        self._inner = inner

    @staticmethod
    def load(path: Union[str, "os.PathLike[str]"]) -> "Scene":
        return Scene(_matfit.Scene.load(os.fspath(path)))

    @property
    def path(self) -> str:
        return str(self._inner.path)

    @property
    def groups(self) -> List[str]:
        """The groups' names (objects of a group share one material)."""
        return list(self._inner.groups)

    @property
    def shape(self) -> tuple:
        """(H, W) of the camera's image."""
        return (self._inner.height, self._inner.width)

    def render(
        self,
        spp: Optional[int] = None,
        seed: Optional[int] = None,
        aov: str = "beauty",
        view: Optional[Union[int, str]] = None,
        progress: Optional[bool] = None,
    ) -> np.ndarray:
        """The path-traced image as float32 (H, W, 3), or an AOV: int32 (H, W) ids for
        "group", "object", "mirror-group", "mirror-object" (-1: nothing); float32 (H, W, 3)
        for "normal", "depth", "uv". spp and seed default to the scene's [render]."""
        p = _progress(progress)
        try:
            return self._inner.render(
                spp=spp,
                seed=seed,
                aov=aov,
                view=None if view is None else str(view),
                progress=p,
            )
        finally:
            _close(p)

    def edit(
        self,
        *,
        edit_files: Sequence[Union[str, "os.PathLike[str]"]] = (),
        remove: Sequence[str] = (),
        move: Sequence[str] = (),
        scale_light: Sequence[str] = (),
        material: Sequence[str] = (),
        add: Sequence[str] = (),
        look_from: Optional[Sequence[float]] = None,
        look_at: Optional[Sequence[float]] = None,
        fov: Optional[float] = None,
    ) -> "Scene":
        """A new scene with the command line's edits applied: edit files first, then
        remove=["NAME"], move=["NAME=DX,DY,DZ"], scale_light=["NAME=K"],
        material=['GROUP={ type = "diffuse", rho_d = 0.5 }'], add=['{ name = ..., shape = ... }'],
        look_from/look_at/fov (docs/USAGE.md, "Edits")."""
        return Scene(
            self._inner.edit(
                edit_files=[os.fspath(f) for f in edit_files],
                remove=list(remove),
                moves=list(move),
                scale_light=list(scale_light),
                material=list(material),
                add=list(add),
                look_from=None if look_from is None else list(look_from),
                look_at=None if look_at is None else list(look_at),
                fov=fov,
            )
        )

    def __repr__(self) -> str:
        return repr(self._inner)


@dataclass
class GroupResult:
    """One group of a recovery: its level and status, every parameter and its 1σ (None where
    the photo does not determine it), ε and its noise floor, as results.json gives them."""

    name: str
    level: str
    status: str
    parameters: Dict[str, Any]
    sigma: Dict[str, Any]
    raw: Dict[str, Any] = field(repr=False)


@dataclass
class Recovery:
    """What matfit.recover gives."""

    groups: Dict[str, GroupResult]
    scene: Scene
    photo: np.ndarray
    synthetic: np.ndarray
    error: np.ndarray
    log: List[Dict[str, Any]] = field(repr=False)
    results: Dict[str, Any] = field(repr=False)
    output: Optional[str] = None


def _group(g: Dict[str, Any]) -> GroupResult:
    params = {k: v for k, v in g.get("params", {}).items()}
    sigma = dict(g.get("sigma", {}) or {})
    return GroupResult(
        name=g["name"],
        level=g.get("level", ""),
        status=g.get("status", ""),
        parameters=params,
        sigma=sigma,
        raw=g,
    )


Photo = Union[str, "os.PathLike[str]", np.ndarray]


def _photo(p: Photo):
    if isinstance(p, np.ndarray):
        a = np.ascontiguousarray(p, dtype=np.float32)
        if a.ndim != 3 or a.shape[2] != 3:
            raise PhotoError(f"a photo array must be (H, W, 3), got {p.shape}")
        return a
    return os.fspath(p)


def recover(
    scene: Scene,
    photos: Union[Photo, Sequence[Photo]],
    *,
    progress: Optional[bool] = None,
    **options: Any,
) -> Recovery:
    """Recovers the materials of the scene's groups from the photos, as `matfit recover` does.

    A photo is a path or a linear float (H, W, 3) array. The options are the command line's
    (underscores for dashes): seed, max_iterations, final_spp, first_pixels, exposure,
    grey_card="card=0.18", exposure_from_lights, camera_is_calibrated, film_shift,
    ignore_mask, response, views, output (a folder: results.json, report.html, checkpoint),
    resume; and any field of results.json's inputs.options. Ctrl-C stops it after the current
    global iteration (KeyboardInterrupt; with output, its checkpoint is kept for resume=True).
    """
    if isinstance(photos, (str, os.PathLike, np.ndarray)):
        photos = [photos]
    opts = dict(options)
    if "output" in opts and opts["output"] is not None:
        opts["output"] = os.fspath(opts["output"])
    p = _progress(progress)
    try:
        r = _matfit.recover(scene._inner, [_photo(x) for x in photos], opts, p)
    finally:
        _close(p)
    results = json.loads(r["results"])
    groups = {g["name"]: _group(g) for g in results.get("groups", [])}
    return Recovery(
        groups=groups,
        scene=Scene(r["scene"]),
        photo=r["photo"],
        synthetic=r["synthetic"],
        error=r["error"],
        log=[json.loads(line) for line in r["log"]],
        results=results,
        output=None if r["output"] is None else str(r["output"]),
    )


def composite(
    scene: Scene,
    photo: Photo,
    *,
    edit_files: Sequence[Union[str, "os.PathLike[str]"]] = (),
    remove: Sequence[str] = (),
    move: Sequence[str] = (),
    scale_light: Sequence[str] = (),
    material: Sequence[str] = (),
    add: Sequence[str] = (),
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    exposure: Optional[float] = None,
    response: str = "srgb",
    progress: Optional[bool] = None,
) -> np.ndarray:
    """The edits of the recovered scene rendered into its photo (differential rendering), as
    `matfit composite` does: float32 (H, W, 3) in the photo's units."""
    p = _progress(progress)
    try:
        return _matfit.composite(
            scene._inner,
            _photo(photo),
            edit_files=[os.fspath(f) for f in edit_files],
            remove=list(remove),
            moves=list(move),
            scale_light=list(scale_light),
            material=list(material),
            add=list(add),
            spp=spp,
            seed=seed,
            exposure=exposure,
            response=response,
            progress=p,
        )
    finally:
        _close(p)


def read_image(path: Union[str, "os.PathLike[str]"]) -> np.ndarray:
    """A linear image file (EXR, HDR, PFM; e.g. a recovery's synthetic.exr) as float32
    (H, W, 3)."""
    return _matfit.read_image(os.fspath(path))
