"""`ermrl video`: a saved agent's episodes rendered to MP4/GIF, decoded back frame by frame."""

import warnings

import imageio.v2 as iio
import imageio.v3 as iio3
import pytest
from PIL import Image, ImageSequence
from test_saved_agent import write_untrained_agent

import ermrl
from ermrl.agent import AgentConfig
from ermrl.analysis.video import gl_backend, write_video
from ermrl.errors import ConfigError

from cli_runs import ermrl as cli, ermrl_process




def mp4_frames(path) -> list:
    """Every frame of an MP4, decoded by imageio-ffmpeg."""
    with warnings.catch_warnings():  # ffmpeg runs in a subprocess, which JAX's fork check warns about
        warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
        reader = iio.get_reader(path, format="FFMPEG")
        try:
            return [frame for frame in reader]  # not list(): the reader says its length is inf
        finally:
            reader.close()


def test_a_cartpole_gif_holds_every_frame(tmp_path):
    path = write_untrained_agent(tmp_path, "CartPoleNoVel-v1", seed=1)
    video = write_video(ermrl.load_agent(path), tmp_path / "v.gif", episodes=2, seed=0, max_steps=30)
    assert video.frames == sum(video.lengths) + 2 and all(0 < n <= 30 for n in video.lengths)
    frames = iio3.imread(video.path, index=None)
    # GIF stores a frame identical to the previous one by lengthening that one's duration (Pillow)
    assert frames.shape[1:] == (400, 600, 3) and video.frames / 2 < len(frames) <= video.frames
    with Image.open(video.path) as gif:
        durations = [frame.info["duration"] for frame in ImageSequence.Iterator(gif)]
    assert video.fps == 50 and sum(durations) == video.frames * 20
    with pytest.raises(ConfigError, match="must end in .mp4 or .gif"):
        write_video(path, tmp_path / "v.avi")


def test_train_saves_agents_that_the_video_command_films(tmp_path):
    run = tmp_path / "run"
    r = cli("train", "--env", "CartPoleNoVel-v1", "--seeds", "1", "--timesteps", "2048", "--out", run, "--quiet")
    assert r.returncode == 0, r.stderr
    assert [p.name for p in (run / "agents").iterdir()] == ["seed0.npz"] and "agents/" in r.stdout
    r = ermrl_process("video", run, "--max-steps", "25")  # pygame and GL set up in a process of their own
    assert r.returncode == 0, r.stderr
    out = run / "videos" / "seed0-env-seed0.mp4"
    assert f"wrote {out}:" in r.stdout and r.stderr == ""
    frames = int(r.stdout.split(f"wrote {out}: ")[1].split(" frames")[0])
    assert len(mp4_frames(out)) == frames and 2 <= frames <= 26


def test_no_saved_agents_is_a_one_line_error(tmp_path):
    run = tmp_path / "run"
    r = cli("train", "--env", "CartPoleNoVel-v1", "--seeds", "1", "--timesteps", "2048", "--out", run, "--quiet",
              "--no-save-agents")
    assert r.returncode == 0, r.stderr
    assert not (run / "agents").exists()
    r = cli("video", run)
    assert r.returncode == 2 and r.stderr == (f"ermrl video: error: {run} has no saved agents (agents/*.npz); "
                                              "`ermrl train` and `ermrl test` save them with --save-agents (the "
                                              "default)\n")
    r = cli("video", tmp_path / "nope")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "does not exist" in r.stderr


def test_a_mujoco_episode_renders_headless(tmp_path):
    try:
        gl_backend()
    except ConfigError as e:
        pytest.skip(str(e))
    path = write_untrained_agent(tmp_path / "run", "Swimmer-v5", agent=AgentConfig(reservoirs=1))
    out = tmp_path / "swimmer.mp4"
    r = ermrl_process("video", "--agent", path, "--max-steps", "30", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "31 frames at 25 fps" in r.stdout
    frames = mp4_frames(out)
    assert len(frames) == 31
    assert frames[0].shape == (480, 480, 3) and frames[0].std() > 5  # a picture, not a blank frame
