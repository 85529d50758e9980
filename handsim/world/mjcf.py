"""MJCF out: write an ``mujoco.MjSpec`` as XML that compiles back to the same model.

``MjSpec.to_xml`` prints numbers with 6 significant digits, which moves masses, inertias and
gains by ~1e-6 relative. :func:`spec_to_xml` prints every number as the shortest decimal that
reads back to the same value (the same ``double``; the same ``float`` for MuJoCo's
single-precision attributes such as ``rgba`` and mesh vertices), so the XML compiles to a model
equal to the in-memory one. Meshes built in memory (``uservert``/``userface``) stay inline in
the string; :func:`save_spec` writes them as OBJ files under an assets folder next to the XML
and points each mesh's ``file`` there (OBJ text keeps vertex order and indices, and the
shortest ``float32`` decimals are exact, so the compiled mesh is bit-identical).

Full precision uses MuJoCo's XML writer setting ``_mjPRIVATE__set_xml_precision`` (the
digits MuJoCo's own round-trip tests use). Where the installed MuJoCo does not export it, the
XML is written at MuJoCo's default precision with a :class:`MjcfPrecisionWarning`.

Output is deterministic: the same spec gives byte-identical files.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import pathlib
import re
import warnings
from collections.abc import Iterator

import mujoco
import numpy as np

from handsim.errors import HandSimError

__all__ = ["MjcfError", "MjcfPrecisionWarning", "spec_to_xml", "save_spec", "write_obj"]

# Attributes that MuJoCo stores as float32 (mjspec.h); their values are printed as the shortest
# float32 decimal. Every other number is printed as the shortest float64 decimal, which is
# exact for float32 values too, only longer.
_FLOAT32_ATTRS = frozenset(
    {
        "rgba",
        "vertex",
        "normal",
        "texcoord",
        "sensorsize",
        "focal",
        "focalpixel",
        "principal",
        "principalpixel",
        "bulbradius",
        "intensity",
        "attenuation",
        "cutoff",
        "softness",
        "exponent",
        "ambient",
        "diffuse",
        "specular",
        "emission",
        "shininess",
        "reflectance",
        "metallic",
        "roughness",
        "texrepeat",
        "inflate",
    }
)
# Attributes whose values are names or paths, never numbers.
_TEXT_ATTRS = frozenset({"name", "class", "childclass", "file", "model", "meshdir", "texturedir"})
_ATTR_RE = re.compile(r' ([A-Za-z_][\w.:-]*)="([^"]*)"')
_FLOAT_TOKEN_RE = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")
_FULL_DIGITS = 17


class MjcfError(HandSimError, ValueError):
    """A spec cannot be written as MJCF (e.g. a mesh that is neither in memory nor a file)."""


class MjcfPrecisionWarning(UserWarning):
    """The installed MuJoCo cannot print full precision; the XML is rounded to 6 digits."""


@functools.cache
def _precision_functions() -> tuple[ctypes._CFuncPtr, ctypes._CFuncPtr] | None:
    # The library the bindings already loaded; dlopen of the same file returns that handle.
    folder = pathlib.Path(mujoco.__file__).parent
    candidates = sorted(folder.glob("libmujoco.so*")) + sorted(folder.glob("libmujoco*.dylib"))
    candidates += sorted(folder.glob("mujoco.dll"))
    for path in candidates:
        try:
            lib = ctypes.CDLL(str(path))
            get, set_ = lib._mjPRIVATE__get_xml_precision, lib._mjPRIVATE__set_xml_precision
        except (OSError, AttributeError):
            continue
        # MuJoCo >= 3.3 stores the precision as a number of significant digits.
        get.restype, get.argtypes = ctypes.c_int, []
        set_.restype, set_.argtypes = None, [ctypes.c_int]
        if 1 <= get() <= _FULL_DIGITS:
            return get, set_
    return None


@contextlib.contextmanager
def _full_precision() -> Iterator[None]:
    functions = _precision_functions()
    if functions is None:
        warnings.warn(
            f"MuJoCo {mujoco.__version__} does not export _mjPRIVATE__set_xml_precision; the "
            "MJCF is written with 6 significant digits and compiles to a model that differs "
            "from the in-memory one by ~1e-6 relative",
            MjcfPrecisionWarning,
            stacklevel=3,
        )
        yield
        return
    get, set_ = functions
    # The setting is thread-local in MuJoCo; to_xml runs on this thread.
    previous = get()
    set_(_FULL_DIGITS)
    try:
        yield
    finally:
        set_(previous)


def _shortest(token: str, float32: bool) -> str:
    if not _FLOAT_TOKEN_RE.match(token) or ("." not in token and "e" not in token.lower()):
        return token
    value = float(token)
    text = repr(value)
    if float32:
        single = np.float32(value)
        if float(single) == value:
            short = str(single)
            # MuJoCo may parse as double and then round to float: check that path.
            if len(short) < len(text) and np.float32(float(short)) == single:
                text = short
    return text[:-2] if text.endswith(".0") else text


def _shorten_numbers(xml: str) -> str:
    def attribute(match: re.Match[str]) -> str:
        key, value = match.group(1), match.group(2)
        if key in _TEXT_ATTRS or not any(c.isdigit() for c in value):
            return match.group(0)
        float32 = key in _FLOAT32_ATTRS
        tokens = value.split(" ")
        return f' {key}="{" ".join(_shortest(t, float32) if t else t for t in tokens)}"'

    return _ATTR_RE.sub(attribute, xml)


def spec_to_xml(spec: mujoco.MjSpec) -> str:
    """The MJCF text of ``spec`` at full precision; in-memory meshes are inline.

    Args:
        spec: the model; it is not modified.

    Returns:
        XML that ``mujoco.MjModel.from_xml_string`` compiles to the same model as
        ``spec.compile()`` (every number and mesh vertex equal).
    """
    with _full_precision():
        xml = spec.to_xml()
    return _shorten_numbers(xml)


def write_obj(path: str | os.PathLike[str], vertices: np.ndarray, faces: np.ndarray) -> None:
    """Write a triangle mesh as Wavefront OBJ (``v`` and ``f`` lines only, deterministic).

    Args:
        path: file to write.
        vertices: (V, 3) positions, metres; written as the shortest float32 decimals, which
            MuJoCo reads back exactly (it stores mesh vertices as float32).
        faces: (F, 3) vertex indices, 0-based (written 1-based, as OBJ requires).
    """
    v = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3) + 1
    # str() of a float32 scalar is its shortest decimal (format() would widen it to float64).
    lines = ["v " + " ".join(map(str, row)) for row in v]
    lines += [f"f {a} {b} {c}" for a, b, c in f.tolist()]
    pathlib.Path(path).write_bytes(("\n".join(lines) + "\n").encode("ascii"))


def save_spec(
    spec: mujoco.MjSpec, path: str | os.PathLike[str], *, assets_dir: str = "assets"
) -> pathlib.Path:
    """Write ``spec`` as an MJCF file plus its meshes (OBJ) in a folder next to it.

    Each mesh built in memory is written to ``<folder of path>/<assets_dir>/<mesh name>.obj``
    and referenced as ``file="<assets_dir>/<mesh name>.obj"``, so the folder can be moved or
    opened with ``python -m mujoco.viewer --mjcf <path>``. Without meshes no folder is made.

    Args:
        spec: the model; it is not modified.
        path: the XML file to write (parent folders are created).
        assets_dir: mesh folder, relative to the XML file's folder.

    Returns:
        The path of the XML file.

    Raises:
        MjcfError: for a mesh loaded from a file (only in-memory meshes are written) or one
            with normals or texture coordinates (OBJ export here keeps positions and faces).
    """
    path = pathlib.Path(path)
    if not isinstance(assets_dir, str) or not assets_dir or pathlib.Path(assets_dir).is_absolute():
        raise MjcfError(
            f"assets_dir must be a non-empty relative folder name; received {assets_dir!r}"
        )
    spec = spec.copy()
    meshes = list(spec.meshes)
    for mesh in meshes:
        if mesh.file or len(mesh.uservert) == 0:
            raise MjcfError(
                f"mesh {mesh.name!r} is not built in memory (file={mesh.file!r}); save_spec "
                "writes only meshes given by uservert/userface"
            )
        if len(mesh.usernormal) or len(mesh.usertexcoord):
            raise MjcfError(
                f"mesh {mesh.name!r} has normals or texture coordinates, which save_spec does "
                "not write; build it from vertices and faces only"
            )
    path.parent.mkdir(parents=True, exist_ok=True)
    if meshes:
        folder = path.parent / assets_dir
        folder.mkdir(parents=True, exist_ok=True)
        # to_xml compiles the spec, reading the mesh files. Meshes of attached specs (the
        # hand's skin) keep their own compiler settings, so neither a parent's meshdir nor its
        # model folder reaches them: compile from absolute paths, then write relative ones.
        absolute = str(folder.resolve())
        for mesh in meshes:
            name = f"{mesh.name}.obj"
            write_obj(folder / name, np.array(mesh.uservert), np.array(mesh.userface))
            mesh.uservert = []
            mesh.userface = []
            mesh.file = f"{absolute}/{name}"
    xml = spec_to_xml(spec)
    if meshes:
        xml = xml.replace(f'file="{absolute}/', f'file="{assets_dir}/')
    path.write_text(xml, encoding="utf-8")
    return path
