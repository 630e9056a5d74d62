"""``ermrl video``: renders episodes of a saved agent to an MP4 or GIF file."""

from __future__ import annotations

import math
from pathlib import Path

from ermrl.cli import options
from ermrl.errors import ConfigError


MIN_FPS, MAX_FPS = 0.1, 1000.0
"""The frame rates a video may have."""
MAX_EPISODES = 100
MAX_SEED = 2**32 - 1
"""Gymnasium seeds an env's NumPy generator, which takes seeds below 2**32 here."""


def add_parser(sub, formatter) -> None:
    p = sub.add_parser("video", help="render episodes of a saved agent to an MP4 or GIF file",
                       description="Load a saved agent (the first one of RUN, or --agent FILE), run it in its "
                                   "Gymnasium env with render_mode='rgb_array' and write the frames with imageio. "
                                   "MuJoCo envs render headless (OSMesa or EGL, see MUJOCO_GL).",
                       formatter_class=formatter)
    p.add_argument("run", type=options.path, nargs="?", default=None,
                   help="run folder (from `ermrl train`, a test phase or a study folder): films its first saved agent")
    p.add_argument("--agent", type=options.path, default=None, metavar="FILE", help="the agent file (.npz) to film")
    p.add_argument("--out", type=options.path, default=None, metavar="FILE.mp4|.gif",
                   help="video file (default RUN/videos/AGENT-env-seedS.mp4)")
    p.add_argument("--episodes", type=int, default=1, help="episodes, one after the other in one file")
    p.add_argument("--seed", type=int, default=0, help="env seed of the first episode (then seed + 1, ...)")
    p.add_argument("--max-steps", type=int, default=None, metavar="N", help="cut each episode after N steps")
    p.add_argument("--stochastic", action="store_true",
                   help="sample actions from the policy instead of taking its mode (argmax or mean)")
    p.add_argument("--fps", type=float, default=None, help="frames per second; None: the env's render_fps")


def run_command(args) -> int:
    from ermrl import storage
    from ermrl.analysis.video import write_video
    from ermrl.saved_agent import load_agent

    if args.agent is None and args.run is None:
        raise ConfigError("give a run folder (ermrl video RUN) or an agent file (--agent FILE)")
    _check_numbers(args)
    if args.run is not None and args.run.is_file():
        raise ConfigError(f"{args.run} is a file, not a run folder; give the folder, or the agent file as --agent "
                          f"{args.run}")
    if args.run is not None and not args.run.is_dir():
        raise ConfigError(f"run folder {args.run} does not exist; give a folder written by `ermrl train` or "
                          "`ermrl test`")
    agent = load_agent(args.agent if args.agent is not None else args.run)
    from ermrl.envs.host_backend import check_mujoco_gl

    check_mujoco_gl(agent.env.base_id)
    folder = args.run if args.run is not None else agent.path.parent
    out = args.out or folder / "videos" / f"{_name(agent.path, folder)}-env-seed{args.seed}.mp4"
    storage.check_file(out)
    video = write_video(agent, out, args.episodes, args.seed, args.max_steps, not args.stochastic, args.fps)
    returns = ", ".join(f"{r:.1f}" for r in video.returns)
    print(f"agent {agent.path} ({agent.env_id}, seed {agent.seed})")
    print(f"wrote {video.path}: {video.frames} frames at {video.fps:g} fps; {len(video.returns)} episode(s), "
          f"returns {returns}, lengths {', '.join(map(str, video.lengths))}")
    return 0


def _check_numbers(args) -> None:
    """One-line errors for the counts, the seed, the frame rate and the file type, before loading anything."""
    from ermrl.analysis.video import FORMATS

    if args.episodes < 1:
        raise ConfigError(f"--episodes must be >= 1, got {args.episodes}")
    if args.max_steps is not None and args.max_steps < 1:
        raise ConfigError(f"--max-steps must be >= 1, got {args.max_steps}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if args.episodes > MAX_EPISODES:
        raise ConfigError(f"--episodes must be <= {MAX_EPISODES} (their frames are held until the file is written), "
                          f"got {args.episodes}")
    if args.seed > MAX_SEED:
        raise ConfigError(f"--seed must be <= {MAX_SEED}, got {args.seed}")
    if args.fps is not None and not (math.isfinite(args.fps) and MIN_FPS <= args.fps <= MAX_FPS):
        raise ConfigError(f"--fps must be between {MIN_FPS:g} and {MAX_FPS:g} frames per second, got {args.fps:g}; or "
                          "leave it out for the env's rate")
    if args.out is not None and args.out.suffix.lower() not in FORMATS:
        raise ConfigError(f"video file {args.out} must end in .mp4 or .gif")


def _name(path: Path, folder: Path) -> str:
    """The agent's name in the video's: its path under ``folder`` without agents/ folders, e.g. ermrl-seed1000."""
    try:
        parts = path.with_suffix("").relative_to(folder).parts
    except ValueError:
        parts = (path.stem,)
    return "-".join(p for p in parts if p != "agents") or path.stem
