"""The OpenGL context (headless EGL, one per process) and shader programs from `kernels/glsl/`."""

from __future__ import annotations

import threading
from functools import cache
from importlib import resources
from pathlib import Path

from chronocl.core.errors import RendererUnavailableError

NO_GL = (
    "cannot create an OpenGL context through EGL ({why}); install the system packages "
    "libegl1 and libgl1-mesa-dri (Mesa llvmpipe renders on the CPU), or a GPU driver"
)

_lock = threading.Lock()
_context = None


def gl_context():
    """The process's headless moderngl context (EGL: a GPU driver where present, else llvmpipe)."""
    global _context
    with _lock:
        if _context is None:
            try:
                import moderngl  # noqa: F401  (its own message when missing)
            except ImportError:
                raise RendererUnavailableError(
                    "moderngl is not installed; 'pip install moderngl'"
                ) from None
            _context = new_egl_context()
        return _context


def new_egl_context():
    """A new standalone OpenGL context on EGL, 4.3 where the driver has it (compute shaders:
    the viewer's recolouring on the GPU), else 3.3; RendererUnavailableError saying why not.

    A driver gives the version asked for: NVIDIA's EGL answers a request for 3.3 with a 3.3
    core context, whose missing compute shaders made every max-mode TF edit integrate."""
    try:
        import moderngl

        try:
            return moderngl.create_context(standalone=True, backend="egl", require=430)
        except Exception:  # a driver without 4.3: the renderer needs 3.3 only
            return moderngl.create_context(standalone=True, backend="egl", require=330)
    except Exception as exc:  # moderngl/glcontext raise plain Exceptions
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RendererUnavailableError(NO_GL.format(why=why)) from None


@cache
def shader_dir() -> Path:
    packaged = Path(str(resources.files("chronocl"))) / "kernels" / "glsl"
    if packaged.is_dir():
        return packaged
    return Path(__file__).resolve().parents[2] / "kernels" / "glsl"


def shader_source(name: str) -> str:
    return (shader_dir() / name).read_text()


def with_defines(source: str, defines: tuple[str, ...]) -> str:
    """`source` with `#define NAME 1` for each of `defines` after its #version line (GLSL
    wants that first); no defines give the source unchanged."""
    if not defines:
        return source
    version, _, rest = source.partition("\n")
    return "\n".join([version, *(f"#define {d} 1" for d in defines), rest])


@cache
def program(ctx, name: str, defines: tuple[str, ...] = ()):
    """The linked program `name` (name.vert + name.frag) on `ctx` with `defines` switched on in
    the fragment shader (e.g. ("SHADING",)), built once per set of defines."""
    return ctx.program(
        vertex_shader=shader_source(f"{name}.vert"),
        fragment_shader=with_defines(shader_source(f"{name}.frag"), defines),
    )
