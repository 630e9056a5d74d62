"""Videos of a saved agent: Gymnasium's ``render_mode="rgb_array"`` frames written with imageio.

MP4 goes through imageio-ffmpeg (its wheel ships an ffmpeg binary), GIF through Pillow; both come with the
``video`` extra. MuJoCo renders without a screen through OSMesa or EGL, chosen by ``MUJOCO_GL``, which must be
set before MuJoCo opens its first renderer: :func:`headless` sets it (and SDL's dummy drivers for pygame's
classic-control envs) here only, never at ``import ermrl``.
"""

from __future__ import annotations

import ctypes.util
import dataclasses
import os
import warnings
from pathlib import Path

import numpy as np

from ermrl.errors import ConfigError
from ermrl.storage import atomic_path

FORMATS = (".mp4", ".gif")
GL_PACKAGES = "libosmesa6"
"""The Debian package that lets MuJoCo render headless with MUJOCO_GL=osmesa (what `make test` installs)."""


@dataclasses.dataclass(frozen=True)
class Video:
    """What :func:`write_video` wrote."""

    path: Path
    frames: int
    """Frames in the file: each episode's reset frame plus one per step."""
    fps: float
    returns: tuple[float, ...]
    """Return of each episode (cut at max_steps when given)."""
    lengths: tuple[int, ...]
    """Steps of each episode."""


def gl_backend() -> str:
    """The MUJOCO_GL value to use: the environment's when set, else osmesa when libOSMesa is installed, else egl
    when libEGL is. Raises ConfigError naming the Debian package when neither is."""
    chosen = os.environ.get("MUJOCO_GL") or os.environ.get("PYOPENGL_PLATFORM")
    if chosen:
        return chosen.lower()
    if ctypes.util.find_library("OSMesa"):
        return "osmesa"
    if ctypes.util.find_library("EGL"):
        return "egl"
    raise ConfigError(f"MuJoCo needs OSMesa or EGL to render without a screen; install one (Debian: apt-get install "
                      f"{GL_PACKAGES}, or libegl1 libgl1-mesa-dri), or set MUJOCO_GL")


def headless(base_id: str) -> None:
    """Prepares the process to render ``base_id`` without a screen; call it before the env is made."""
    from ermrl.envs.host_backend import extra_for

    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # pygame prints a banner on stdout at import
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")  # pygame.init() would look for a sound card
    if extra_for(base_id) == "mujoco":
        os.environ["MUJOCO_GL"] = gl_backend()


def _writer(path: Path, fps: float):
    """An imageio writer for ``path`` (.mp4 or .gif), or a ConfigError naming the missing package."""
    try:
        import imageio.v2 as iio
    except ImportError:
        raise ConfigError("videos need imageio; run: pip install 'ermrl[video]'") from None
    if path.suffix.lower() == ".gif":
        return iio.get_writer(path, mode="I", duration=1000.0 / fps, loop=0)
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        raise ConfigError("MP4 videos need imageio-ffmpeg; run: pip install 'ermrl[video]', or write a .gif") from None
    return iio.get_writer(path, format="FFMPEG", fps=fps, codec="libx264", macro_block_size=1,
                          ffmpeg_log_level="error")


def _even(frame: np.ndarray) -> np.ndarray:
    """Pads (H, W, 3) to even H and W by repeating the last row/column (H.264's 4:2:0 needs even sizes)."""
    h, w = frame.shape[:2]
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge") if h % 2 or w % 2 else frame


def write_video(agent, out: Path | str, episodes: int = 1, seed: int = 0, max_steps: int | None = None,
                deterministic: bool = True, fps: float | None = None) -> Video:
    """Renders ``episodes`` episodes of ``agent`` (a :class:`~ermrl.saved_agent.SavedAgent` or the path of one)
    one after the other into ``out`` (.mp4 or .gif, written atomically). Episode e is reset with ``seed + e``
    and cut after ``max_steps`` steps; ``fps`` defaults to the env's render_fps."""
    out = Path(out)
    if out.suffix.lower() not in FORMATS:
        raise ConfigError(f"video file {out} must end in .mp4 or .gif")
    if episodes < 1:
        raise ConfigError(f"`episodes` must be >= 1, got {episodes}", owner=write_video)
    if max_steps is not None and max_steps < 1:
        raise ConfigError(f"`max_steps` must be >= 1, got {max_steps}", owner=write_video)
    if not hasattr(agent, "act"):
        from ermrl.saved_agent import load_agent

        agent = load_agent(agent)
    headless(agent.env.base_id)
    env = agent.make_env(render_mode="rgb_array")
    fps = float(fps or env.metadata.get("render_fps") or 30)
    returns, lengths, frames = [], [], 0
    try:
        with atomic_path(out) as tmp, warnings.catch_warnings():
            # imageio-ffmpeg starts ffmpeg with subprocess (fork + exec), which JAX warns about; it is safe
            warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
            writer = _writer(tmp, fps)
            try:
                for e in range(episodes):
                    obs, _ = env.reset(seed=seed + e)
                    agent.reset()
                    writer.append_data(_even(_render(env, agent)))
                    frames += 1
                    reward, done, total, steps = None, False, 0.0, 0
                    while not done and (max_steps is None or steps < max_steps):
                        obs, reward, terminated, truncated, _ = env.step(agent.act(obs, reward, deterministic))
                        writer.append_data(_even(env.render()))
                        frames, steps, total = frames + 1, steps + 1, total + float(reward)
                        done = terminated or truncated
                    returns.append(total)
                    lengths.append(steps)
            finally:
                writer.close()
    finally:
        env.close()
    return Video(out, frames, fps, tuple(returns), tuple(lengths))


def _render(env, agent) -> np.ndarray:
    """The first frame, with a one-line error when the renderer cannot start."""
    try:
        frame = env.render()
    except Exception as e:  # OpenGL/MuJoCo failures come as many types
        first = (str(e).strip().splitlines() or [""])[0]
        gl = f" with MUJOCO_GL={os.environ['MUJOCO_GL']}" if "MUJOCO_GL" in os.environ else ""
        raise ConfigError(f"cannot render {agent.env.base_id}{gl} ({type(e).__name__}: {first}); on Debian "
                          f"install {GL_PACKAGES} (apt-get install {GL_PACKAGES}) or try MUJOCO_GL=egl") from None
    if frame is None or np.ndim(frame) != 3:
        raise ConfigError(f"{agent.env.base_id} rendered no RGB frame (got {type(frame).__name__})")
    return np.asarray(frame)
