"""The bad-input matrix of test_bad_input.py: (command line, the exact one line it must print on stderr), across
every command. The command lines run in a copy of that file's working folder (a plain file, a folder, a malformed
curves.csv, damaged config files, an npz that is no agent, and ``studies.db`` with the studies ``empty``,
``one`` and ``plain``)."""

SQLITE = "sqlite:///studies.db"
STEPS = ("cartpole pendulum pendulum_medium pendulum_paper pendulum_lr1e4 lunarlander lunarlander_1res "
         "lunarlander_medium lunarlander_lr3e4 probe h2 c8 fft fft_early h3 humanoid c13 c16 hpmap c11 c11_2res peer "
         "seed_schedule seed_schedule_paper observed_units observed_units_lr3e4 fitness_1m sizes sizes_medium "
         "sizes_medium_lr3e4 probe_sizes pendulum_paper_500u pendulum_paper_500u_interim pendulum_500u_lr1e4 "
         "pendulum_500u_near_default pendulum_500u_near_default_wide pendulum_500u_near_default_wide_50 "
         "pendulum_500u_more_seeds pendulum_100u_near_default_wide deterministic_eval pendulum_rlzoo_ppo "
         "pendulum_normalize pendulum_rlzoo_sde pendulum_rlzoo_policy pendulum_rlzoo_evolve pendulum_rlzoo_lstm "
         "recurrent_vs_ermrl other_hps h2_converged h2_converged_interim h3_converged h3_converged_interim c8_converged "
         "c3_converged").split()
"""`ermrl reproduce`'s steps, in order."""

CASES = [
    # -- train: numbers, env ids, flags, paths --------------------------------------------------------------
    ("train --timestep 1000", "ermrl train: error: unrecognized arguments: --timestep 1000 (did you mean "
                              "--timesteps?); see `ermrl train --help`"),  # an abbreviation is refused, not expanded
    ("evolve --until-conv", "ermrl evolve: error: unrecognized arguments: --until-conv (did you mean "
                            "--until-converged?); see `ermrl evolve --help`"),
    ("train --units 0", "ermrl train: error: units must be >= 1, got 0; a reservoir needs at least one neuron"),
    ("train --units -5", "ermrl train: error: units must be >= 1, got -5; a reservoir needs at least one neuron"),
    ("train --units abc", "ermrl train: error: argument --units: invalid int value: 'abc'; see `ermrl train --help`"),
    ("train --timesteps 0", "ermrl train: error: total timesteps must be >= 1, got 0"),
    ("train --timesteps 1e5",
     "ermrl train: error: argument --timesteps: invalid int value: '1e5'; see `ermrl train --help`"),
    ("train --seeds 0", "ermrl train: error: --seeds must be >= 1, got 0"),
    ("train --snapshot-every -1", "ermrl train: error: --snapshot-every must be >= 0 seconds, got -1.0"),
    ("test --study s --env-workers x",
     "ermrl test: error: argument --env-workers: must be 'auto' or an integer >= 0, got 'x'; see `ermrl test --help`"),
    ("train --sr nan", "ermrl train: error: --sr must be positive and finite, got [nan]"),
    ("train --sr inf", "ermrl train: error: --sr must be positive and finite, got [inf]"),
    ("train --iss -1", "ermrl train: error: --iss must be positive and finite, got [-1.0]"),
    ("train --iss 1e38", "ermrl train: error: --iss must be <= 1e+06 (the reservoir's float32 sums stay finite), got "
                         "[9.999999680285692e+37]"),
    ("train --leak-rate 0", "ermrl train: error: --leak-rate must be positive and finite, got [0.0]"),
    ("train --lr 3e-4", "ermrl train: error: --lr is ambiguous: the reservoir's leak rate is --leak-rate, PPO's "
                        "learning rate is --learning-rate (in a test phase, the PPO baselines': "
                        "--baseline-learning-rate); see `ermrl train --help`"),
    ("evolve --min-lr 0.1", "ermrl evolve: error: --min-lr is ambiguous: the reservoir's leak rate is "
                            "--min-leak-rate, PPO's learning rate is --learning-rate (in a test phase, the PPO "
                            "baselines': --baseline-learning-rate); see `ermrl evolve --help`"),
    ("train --env CartPolee-v1", "ermrl train: error: unknown env id 'CartPolee-v1': Gymnasium has no "
                                 "'CartPolee-v1'; did you mean CartPole-v1, CartPole-v0, CartPoleNoVel-v1?"),
    ("train --env Blackjack-v1", "ermrl train: error: env 'Blackjack-v1' has observation space Tuple(Discrete(32), "
                                 "Discrete(11), Discrete(2)); only 1-D Box observations are supported"),
    ("train --env LunarLander-v3 --backend jax", "ermrl train: error: env 'LunarLander-v3' has no JAX version; use "
                                                 "--backend host or auto (the JAX backend runs: Acrobot-v1, CartPole-v1, "
                                                 "CartPoleNoVel-v1, MountainCar-v0, MountainCarContinuous-v0, "
                                                 "MountainCarContinuousNoVel-v0, MountainCarNoVel-v0, Pendulum-v1, "
                                                 "PendulumNoVel-v1)"),
    ("train --backend gpu", "ermrl train: error: argument --backend: invalid choice: 'gpu' (choose from 'auto', "
                            "'jax', 'mujoco', 'host'); see `ermrl train --help`"),
    ("train --env-threads 0", "ermrl train: error: argument --env-threads: must be 'auto' or an integer in 1..4096, "
                              "got '0'; see `ermrl train --help`"),
    ("train --processes 0", "ermrl train: error: argument --processes: must be an integer in 1..256, got '0'; see "
                            "`ermrl train --help`"),
    ("train --env LunarLander-v3 --backend mujoco", "ermrl train: error: env 'LunarLander-v3' has no batched MuJoCo "
     "version; use --backend host or auto (the MuJoCo backend runs: Ant-v5, HalfCheetah-v5, Hopper-v5, Humanoid-v5, "
     "HumanoidStandup-v5, Swimmer-v5, Walker2d-v5)"),
    ("train --reservoirs -1", "ermrl train: error: reservoirs must be in 0..100, got -1"),
    ("train --reservoirs 100000000000000000000", "ermrl train: error: reservoirs must be in 0..100, got "
     "100000000000000000000"),
    ("train --n-epochs 100000000000000000000", "ermrl train: error: n_epochs must be <= 1000 (SB3's default is 10), "
     "got 100000000000000000000"),
    ("evolve --trials 100000000000000000000", "ermrl evolve: error: --trials must be <= 100,000 (the paper's studies "
     "have 900), got 100000000000000000000"),
    ("train --rc-connectivity 0", "ermrl train: error: rc_connectivity must be in (0, 1], got 0.0; it is a fraction "
                                  "of the weights (ReservoirPy's default: 0.1)"),
    ("evolve --input-connectivity 1.5", "ermrl evolve: error: input_connectivity must be in (0, 1], got 1.5; it is a "
                                        "fraction of the weights (ReservoirPy's default: 0.1)"),
    ("train --bias-scaling -1", "ermrl train: error: bias_scaling must be a finite number >= 0, got -1.0"),
    ("train --observed-units 1000", "ermrl train: error: observed_units must be in [1, 100], got 1000"),
    ("train --env-workers -1", "ermrl train: error: argument --env-workers: must be 'auto' or an integer >= 0, got "
                               "'-1'; see `ermrl train --help`"),
    ("train --learning-rate nan", "ermrl train: error: learning rate nan is outside (0, 1); the paper uses 3e-4 or "
                                  "1e-4"),
    ("train --gamma 1.5", "ermrl train: error: gamma 1.5 is outside (0, 1]; SB3's default is 0.99"),
    ("evolve --gae-lambda -0.1", "ermrl evolve: error: gae_lambda -0.1 is outside [0, 1]; SB3's default is 0.95"),
    ("train --clip-range 0", "ermrl train: error: clip_range must be positive and finite, got 0.0; SB3's default is 0.2"),
    ("baselines --env CartPole-v1 --ent-coef inf",
     "ermrl baselines: error: ent_coef must be >= 0 and finite, got inf; SB3's default is 0.0"),
    ("train --n-envs 4 --n-steps 1000 --batch-size 3000",
     "ermrl train: error: batch_size 3000 must divide n_steps × n_envs = 4000; pick a divisor of 4000"),
    ("train --n-epochs 0", "ermrl train: error: n_envs, n_steps, batch_size and n_epochs must all be >= 1"),
    ("train --n-envs 0", "ermrl train: error: n_envs, n_steps, batch_size and n_epochs must all be >= 1"),
    ("evolve --n-steps 2.5",
     "ermrl evolve: error: argument --n-steps: invalid int value: '2.5'; see `ermrl evolve --help`"),
    ("train --vf-coef -1", "ermrl train: error: vf_coef must be >= 0 and finite, got -1.0; SB3's default is 0.5"),
    ("train --max-grad-norm 0",
     "ermrl train: error: max_grad_norm must be positive and finite, got 0.0; SB3's default is 0.5"),
    ("train --use-sde", "ermrl train: error: --use-sde needs continuous (Box) actions; CartPoleNoVel-v1's actions are "
                        "discrete"),
    ("train --env PendulumNoVel-v1 --use-sde --sde-sample-freq 0",
     "ermrl train: error: sde_sample_freq must be -1 (one exploration matrix per rollout) or >= 1, got 0"),
    ("train --net-arch 64 0",
     "ermrl train: error: net_arch must be one or more layer widths >= 1, got [64, 0]; SB3's default is 64 64"),
    ("train --ortho-init=no", "ermrl train: error: argument --ortho-init/--no-ortho-init: ignored explicit argument "
                              "'no'; see `ermrl train --help`"),
    ("train --activation sigmoid", "ermrl train: error: argument --activation: invalid choice: 'sigmoid' (choose from "
                                   "'tanh', 'relu'); see `ermrl train --help`"),
    ("train --model lstm --use-sde", "ermrl train: error: --use-sde needs continuous (Box) actions; CartPoleNoVel-v1's "
                                     "actions are discrete"),
    ("train --gamma x", "ermrl train: error: argument --gamma: invalid float value: 'x'; see `ermrl train --help`"),
    ("train --reservoirs 2 --sr 1 2 3", "ermrl train: error: --sr got 3 values for 2 reservoirs; give one value or 2"),
    ("train --model lstm --skip-connection",
     "ermrl train: error: --skip-connection feeds the observation beside a reservoir's context, but --model lstm has "
     "no reservoir and already sees the observation; drop --skip-connection"),
    ("train --model lstm --env LunarLander-v3",
     "ermrl train: error: the LSTM baseline (--model lstm) runs on the JAX backend only, and LunarLander-v3 would "
     "run on the host (backend 'auto'); JAX envs: Acrobot-v1, CartPole-v1, CartPoleNoVel-v1, MountainCar-v0, "
     "MountainCarContinuous-v0, MountainCarContinuousNoVel-v0, MountainCarNoVel-v0, Pendulum-v1, PendulumNoVel-v1"),
    ("train --out ''", "ermrl train: error: argument --out: is an empty path; give a path, or leave the option out "
     "for its default; see `ermrl train --help`"),
    ("train --out mine", "ermrl train: error: --out mine holds files that `ermrl train` did not write (agents) and no "
     "config.json of its run; give a new or empty folder, or one that `ermrl train` wrote"),
    ("train --out notes", "ermrl train: error: notes.snapshot is in the way: the run keeps its snapshot there, and it "
     "is not one (or is damaged); move it away or give another --out"),
    ("train --out fresh --first-seed 0 --out mine", "ermrl train: error: --out mine holds files that `ermrl train` "
     "did not write (agents) and no config.json of its run; give a new or empty folder, or one that `ermrl train` "
     "wrote"),
    ("train --out phase", "ermrl train: error: --out phase holds files that `ermrl train` did not write (agents, "
     "test_config.json) and no config.json of its run; give a new or empty folder, or one that `ermrl train` wrote"),
    ("train --out .", "ermrl train: error: --out . holds files that `ermrl train` did not write (adir, adir.toml, "
     "afile, ...) and no config.json of its run; give a new or empty folder, or one that `ermrl train` wrote"),
    ("train --first-seed 100000000000000000000", "ermrl train: error: --first-seed + --seeds - 1 must be <= "
     "2147483647 (seeds are 32-bit integers), got 100000000000000000002"),
    ("train --first-seed 2147483647 --seeds 2", "ermrl train: error: --first-seed + --seeds - 1 must be <= 2147483647 "
     "(seeds are 32-bit integers), got 2147483648"),
    ("train --units 2000000", "ermrl train: error: this run needs at least MEM GiB of memory (3 agents × 1 reservoir "
     "of 2000000 units, 1 envs × 2048 steps per rollout), more than this machine's MEM GiB; lower --units, --seeds, "
     "--popsize, --n-envs or --n-steps"),
    ("train --timesteps 100000000000000000000", "ermrl train: error: total timesteps must be <= 1,000,000,000 per "
     "agent (about a day at 10k steps/s; the paper's longest run is 3M), got 100,000,000,000,000,000,000"),
    ("train --tensorboard ''", "ermrl train: error: argument --tensorboard: is an empty path; give a path, or leave "
     "the option out for its default; see `ermrl train --help`"),
    ("train --out afile", "ermrl train: error: --out afile is a file, not a folder; give a folder path (it is created "
                          "if missing)"),
    ("train --out afile/run", "ermrl train: error: --out afile/run: its parent afile is a file, not a folder; give a "
                              "folder path (it is created if missing)"),
    ("train --tensorboard afile", "ermrl train: error: --tensorboard afile is a file, not a folder; give a folder "
                                  "path (it is created if missing)"),
    ("train --colour red", "ermrl train: error: unrecognized arguments: --colour red; see `ermrl train --help`"),
    ("evolve --popsise 5", "ermrl evolve: error: unrecognized arguments: --popsise 5 (did you mean --popsize?); see "
                           "`ermrl evolve --help`"),
    # -- config files -------------------------------------------------------------------------------------
    ("train --config missing.toml", "ermrl train: error: config file missing.toml does not exist; give the path of "
                                    "a .toml or .yaml file"),
    ("train --config adir.toml", "ermrl train: error: config file adir.toml is a folder; give the path of a .toml "
                                 "or .yaml file"),
    ("train --config x.json", "ermrl train: error: config file x.json must end in .toml, .yaml or .yml"),
    ("train --config list.yaml", "ermrl train: error: config file list.yaml must hold a table of option = value "
                                 "pairs"),
    ("train --config scalar.yaml", "ermrl train: error: config file scalar.yaml must hold a table of option = value "
                                   "pairs"),
    ("train --config bad.toml", "ermrl train: error: config file bad.toml is not valid TOML (Invalid value (at line "
                                "1, column 9))"),
    ("train --config latin1.toml", "ermrl train: error: config file latin1.toml is not UTF-8 text (byte 9); save it "
                                   "as UTF-8"),
    ("train --config unk.toml", "ermrl train: error: config file unk.toml: unknown option 'unitz' for `ermrl train`; "
                                "did you mean 'units'?"),
    ("train --config evolvekey.toml",
     "ermrl train: error: config file evolvekey.toml: unknown option 'trials' for `ermrl train`; options here: "
     "activation, backend, batch-size, bias, bias-scaling, clip-range, ent-coef, env, env-threads, env-workers, "
     "feed-action, first-seed, gae-lambda, gamma, input-connectivity, iss, leak-rate, learning-rate, lstm-hidden, "
     "lstm-seq-len, max-grad-norm, model, n-envs, n-epochs, n-steps, net-arch, no-reservoir, normalize, "
     "observed-units, ortho-init, out, preset, processes, quiet, rc-connectivity, reservoirs, save-agents, sde-sample-freq, "
     "seeds, skip-connection, snapshot-every, sr, tensorboard, timesteps, units, use-sde, vf-coef"),
    ("train --config str.toml", "ermrl train: error: config file str.toml: units has the wrong type: 'ten'; give an "
                                "integer"),
    ("train --config float.toml", "ermrl train: error: config file float.toml: units must be an integer, got 2.5"),
    ("train --config timesteps.yaml", "ermrl train: error: config file timesteps.yaml: timesteps has the wrong type: "
                                      "'1e5'; give an integer"),
    ("train --config many.toml", "ermrl train: error: config file many.toml: units takes one value, got a list "
                                 "[10, 20]"),
    ("train --config nested.toml", "ermrl train: error: config file nested.toml: units has the wrong type: "
                                   "{'n': 1}; give an integer"),
    ("train --config choice.toml", "ermrl train: error: config file choice.toml: bias must be one of bernoulli, "
                                   "none, got 'gaussian'"),
    ("train --config bool.toml", "ermrl train: error: config file bool.toml: skip-connection must be true or false, "
                                 "got 1"),
    # -- evolve: the search, the study, the storage ---------------------------------------------------------
    ("evolve --popsize 1", "ermrl evolve: error: --popsize must be >= 2 (CMA-ES needs at least 2 candidates a "
                           "generation), got 1"),
    ("evolve --popsize -3", "ermrl evolve: error: --popsize must be >= 2 (CMA-ES needs at least 2 candidates a "
                            "generation), got -3"),
    ("evolve --converged-width 0", "ermrl evolve: error: --converged-width must be in (0, 10] decades, got 0.0"),
    ("evolve --converged-generations 0", "ermrl evolve: error: --converged-generations must be in 1..1000, got 0"),
    ("evolve --until-converged --sampler random", "ermrl evolve: error: --until-converged reads CMA-ES's search "
     "distribution; --sampler random has none (use --sampler cmaes, or stop at --trials)"),
    (f"convergence --study one --storage {SQLITE}", "ermrl convergence: error: study 'one' holds no CMA-ES search "
     "distribution yet (it needs 2 generations told); evolve it further first"),
    (f"convergence --study one --storage {SQLITE} --converged-width -1",
     "ermrl convergence: error: --converged-width must be in (0, 10] decades, got -1.0"),
    ("evolve --sampler-seed -1", "ermrl evolve: error: --sampler-seed must be in 0..4294967295 (NumPy's seeds), got -1"),
    ("evolve --sampler-seed 100000000000000000000",
     "ermrl evolve: error: --sampler-seed must be in 0..4294967295 (NumPy's seeds), got 100000000000000000000"),
    ("evolve --heartbeat-interval 10000000000000000000", "ermrl evolve: error: --heartbeat-interval and --grace-period "
     "must be <= 86400 seconds (a day), got 10000000000000000000 and 60"),
    ("evolve --grace-period 100000000", "ermrl evolve: error: --heartbeat-interval and --grace-period must be <= 86400 "
     "seconds (a day), got 10 and 100000000"),
    ("evolve --worker-index 100000000000000000000",
     "ermrl evolve: error: --worker-index must be <= 2,147,483,647, got 100000000000000000000"),
    ("evolve --units 200000", "ermrl evolve: error: a generation needs at least MEM GiB of memory (21 agents × 1 "
     "reservoir of 200000 units, 1 envs × 2048 steps per rollout), more than this machine's MEM GiB; lower --units, "
     "--seeds, --popsize, --n-envs or --n-steps"),
    ("evolve --popsize 1000000 --units 5000", "ermrl evolve: error: a generation needs at least MEM GiB of memory "
     "(2700 agents × 1 reservoir of 5000 units, 1 envs × 2048 steps per rollout), more than this machine's MEM GiB; "
     "lower --units, --seeds, --popsize, --n-envs or --n-steps"),
    ("evolve --timesteps 100000000000000000000", "ermrl evolve: error: total timesteps must be <= 1,000,000,000 per "
     "agent (about a day at 10k steps/s; the paper's longest run is 3M), got 100,000,000,000,000,000,000"),
    ("evolve --storage ''", "ermrl evolve: error: argument --storage: is empty; give sqlite:///PATH.db, a journal file "
     "PATH.log or a database URL, or leave --storage out for the study's own sqlite file; see `ermrl evolve --help`"),
    ("evolve --study ../../esc", "ermrl evolve: error: --study '../../esc' is not a plain name (it holds '/'); a "
     "study's files go in runs/NAME, so give a name without / or \\ (e.g. cartpole-1res), and --out or --storage to "
     "put them elsewhere"),
    ("evolve --study /tmp/esc", "ermrl evolve: error: --study '/tmp/esc' is not a plain name (it holds '/'); a "
     "study's files go in runs/NAME, so give a name without / or \\ (e.g. cartpole-1res), and --out or --storage to "
     "put them elsewhere"),
    ("evolve --study ..", "ermrl evolve: error: --study '..' is not a plain name (it is only dots); a study's files go "
     "in runs/NAME, so give a name without / or \\ (e.g. cartpole-1res), and --out or --storage to put them "
     "elsewhere"),
    ("evolve --study " + "s" * 300, "ermrl evolve: error: --study is 300 characters long; give a name of at most 100"),
    ("report --study '..\\x'", "ermrl report: error: --study '..\\\\x' is not a plain name (it holds '\\\\'); a "
     "study's files go in runs/NAME, so give a name without / or \\ (e.g. cartpole-1res), and --out or --storage to "
     "put them elsewhere"),
    ("select --study a/../../b", "ermrl select: error: --study 'a/../../b' is not a plain name (it holds '/'); a "
     "study's files go in runs/NAME, so give a name without / or \\ (e.g. cartpole-1res), and --out or --storage to "
     "put them elsewhere"),
    ("dashboard --study ../x", "ermrl dashboard: error: --study '../x' is not a plain name (it holds '/'); a study's "
     "files go in runs/NAME, so give a name without / or \\ (e.g. cartpole-1res), and --out or --storage to put "
     "them elsewhere"),
    ("analyze hp-map ../x --out fig.png", "ermrl analyze: error: --study '../x' is not a plain name (it holds '/'); a "
     "study's files go in runs/NAME, so give a name without / or \\ (e.g. cartpole-1res), and --out or --storage to "
     "put them elsewhere"),
    ("evolve --seed-schedule weekly", "ermrl evolve: error: argument --seed-schedule: invalid choice: 'weekly' "
                                      "(choose from 'fixed', 'generation'); see `ermrl evolve --help`"),
    ("evolve --trials 0", "ermrl evolve: error: --trials must be >= 1, got 0"),
    ("evolve --seeds 0", "ermrl evolve: error: --seeds must be >= 1, got 0"),
    ("evolve --sampler grid", "ermrl evolve: error: unknown sampler 'grid'; choose one of cmaes, random, tpe"),
    ("evolve --min-sr 0", "ermrl evolve: error: bad sr bounds [0.0, 100.0]: need 0 < --min-sr < --max-sr "
                          "(log-uniform)"),
    ("evolve --max-sr inf", "ermrl evolve: error: bad sr bounds [0.0001, inf]: need 0 < --min-sr < --max-sr "
                            "(log-uniform)"),
    ("evolve --min-sr 10 --max-sr 1", "ermrl evolve: error: bad sr bounds [10.0, 1.0]: need 0 < --min-sr < --max-sr "
                                      "(log-uniform)"),
    ("evolve --max-leak-rate 2", "ermrl evolve: error: bad leak-rate bounds [0.01, 2.0]: a leak rate is at most 1; set "
                                 "--max-leak-rate to 1"),
    ("evolve --fixed-iss nan", "ermrl evolve: error: --fixed-iss must be positive, got nan"),
    ("evolve --reservoirs 0", "ermrl evolve: error: evolution needs at least 1 reservoir, got 0"),
    ("evolve --normalization minmax", "ermrl evolve: error: argument --normalization: invalid choice: 'minmax' "
                                      "(choose from 'episodic', 'reference'); see `ermrl evolve --help`"),
    ("evolve --env CartPole-v1 --env CartPole-v1", "ermrl evolve: error: --env lists an env twice: CartPole-v1, "
                                                   "CartPole-v1; give each env once"),
    ("evolve --env CartPole-v1 --env Pendulum-v1 --baselines afile",
     "ermrl evolve: error: baselines table afile is damaged (Expecting value: line 1 column 1 (char 0)); fix it or "
     "delete it and rerun `ermrl baselines`"),
    ("evolve --env CartPole-v1 --env Pendulum-v1 --baselines adir",
     "ermrl evolve: error: --baselines adir is a folder; give a file path such as adir/baselines.json"),
    ("evolve --batch 0", "ermrl evolve: error: --batch must be >= 1, got 0"),
    ("evolve --heartbeat-interval 0", "ermrl evolve: error: --heartbeat-interval must be >= 1 (seconds), got 0"),
    ("evolve --heartbeat-interval 30 --grace-period 30",
     "ermrl evolve: error: --grace-period (30 s) must be longer than --heartbeat-interval (30 s), or live trials "
     "would be failed as lost"),
    ("evolve --worker-index -1", "ermrl evolve: error: --worker-index must be >= 0, got -1"),
    ("evolve --study ''", "ermrl evolve: error: --study is empty; give the study's name (e.g. cartpole-1res), or "
                          "leave --study out for `ermrl evolve` to name it"),
    ("evolve --out afile", "ermrl evolve: error: --out afile is a file, not a folder; give a folder path (it is "
                           "created if missing)"),
    ("evolve --snapshots afile", "ermrl evolve: error: --snapshots afile is a file, not a folder; give a folder "
                                 "path (it is created if missing)"),
    ("evolve --storage foo://db", "ermrl evolve: error: cannot open storage 'foo://db' (Can't load plugin: "
                                  "sqlalchemy.dialects:foo); use sqlite:///PATH.db, a journal file PATH.log, or a "
                                  "reachable database URL"),
    ("evolve --storage afile", "ermrl evolve: error: cannot open storage 'afile' (Could not parse SQLAlchemy URL from "
                               "given URL string); use sqlite:///PATH.db, a journal file PATH.log, or a reachable "
                               "database URL"),
    ("evolve --storage notes.log", "ermrl evolve: error: cannot open storage 'notes.log' (notes.log is not an Optuna "
     "journal: its first line is no journal record); use sqlite:///PATH.db, a journal file PATH.log, or a reachable "
     "database URL"),
    ("evolve --storage sqlite:///tiny.db", "ermrl evolve: error: cannot open storage 'sqlite:///tiny.db' (tiny.db is "
     "not a SQLite database); use sqlite:///PATH.db, a journal file PATH.log, or a reachable database URL"),
    ("evolve --storage sqlite:///other.db", "ermrl evolve: error: cannot open storage 'sqlite:///other.db' (other.db "
     "is a SQLite database of another program (tables notes), not an Optuna study database); use sqlite:///PATH.db, a "
     "journal file PATH.log, or a reachable database URL"),
    ("report --study k --storage sqlite:///other.db", "ermrl report: error: other.db is not an Optuna study database "
     "(no 'studies' table); give the study.db that `ermrl evolve` wrote (--storage/--out), or run `ermrl evolve` "
     "to create the study"),
    ("evolve --env CartPole-v1 --env Pendulum-v1 --baselines list.json", "ermrl evolve: error: baselines table "
     "list.json is damaged (needs a 'random' table and a 'ppo' list); fix it or delete it and rerun `ermrl baselines`"),
    ("evolve --storage junk.log", "ermrl evolve: error: cannot open storage 'junk.log' (junk.log is not an Optuna "
     "journal: its first line is no journal record); use sqlite:///PATH.db, a journal file PATH.log, or a reachable "
     "database URL"),
    ("select --study s --storage junk.log", "ermrl select: error: cannot open storage 'junk.log' (junk.log is not an Optuna "
     "journal: its first line is no journal record); use sqlite:///PATH.db, a journal file PATH.log, or a reachable "
     "database URL"),
    (f"evolve --study one --storage {SQLITE} --units 50",
     "ermrl evolve: error: study 'one' already exists with another config (popsize: 6 in the study, 7 here; "
     "search_space.iss: {\"fixed\": 1.0} in the study, [0.1, 10.0] here; seeds: 1 in the study, 3 here; ...); rerun "
     "with the same settings to resume it, or pick a new --study"),
    (f"evolve --study one --storage {SQLITE} --units 50 --popsize 6 --seeds 1 --fixed-iss 1 --timesteps 2048",
     "ermrl evolve: error: study 'one' already exists with another config (train.agent.spec.units: 100 in the "
     "study, 50 here); rerun with the same settings to resume it, or pick a new --study"),
    (f"evolve --study one --storage {SQLITE} --env CartPoleNoVel-v1 --env Pendulum-v1 --popsize 6 --seeds 1 "
     "--fixed-iss 1 --timesteps 2048", "ermrl evolve: error: study 'one' already exists with another config (envs: "
     "[\"CartPoleNoVel-v1\"] in the study, [\"CartPoleNoVel-v1\", \"Pendulum-v1\"] here); rerun with the same settings "
     "to resume it, or pick a new --study"),
    # -- select, test, report: missing studies and their numbers -------------------------------------------
    ("select", "ermrl select: error: the following arguments are required: --study; see `ermrl select --help`"),
    ("select --study nope", "ermrl select: error: no study 'nope': runs/nope/study.db does not exist; run `ermrl "
                            "evolve` first or pass --storage/--out"),
    (f"select --study nope --storage {SQLITE}", "ermrl select: error: no study 'nope' in 'sqlite:///studies.db'; "
                                                "studies there: empty, one, plain"),
    (f"select --study empty --storage {SQLITE}", "ermrl select: error: study 'empty' has no completed trial yet; run "
                                                 "`ermrl evolve` first"),
    (f"select --study plain --storage {SQLITE}", "ermrl select: error: study 'plain' was not made by `ermrl evolve` "
                                                 "(no 'ermrl' attribute)"),
    (f"select --study one --storage {SQLITE} --top 0", "ermrl select: error: --top and --seeds must be >= 1, got 0 "
                                                       "and 5"),
    ("select --study s --storage missing.log", "ermrl select: error: no study 's': missing.log does not exist; run "
                                               "`ermrl evolve` first or pass --storage/--out"),
    ("test --study s --seeds 0", "ermrl test: error: --seeds must be in 1..10,000 (the paper tests on 10), got 0"),
    ("test --study s --learning-rate 2", "ermrl test: error: learning rate 2.0 is outside (0, 1); the paper uses 3e-4 "
                                         "or 1e-4"),
    ("test --study one --storage sqlite:///studies.db --seeds 1000000", "ermrl test: error: --seeds must be in "
     "1..10,000 (the paper tests on 10), got 1000000"),
    ("test --study one --storage sqlite:///studies.db --timesteps 100000000000000000000", "ermrl test: error: total "
     "timesteps must be <= 1,000,000,000 per agent (about a day at 10k steps/s; the paper's longest run is 3M), got "
     "100,000,000,000,000,000,000"),
    ("select --study one --storage sqlite:///studies.db --seeds 100000000", "ermrl select: error: the selection needs "
     "at least MEM GiB of memory (100000000 agents × 1 reservoir of 100 units, 1 envs × 2048 steps per rollout), more "
     "than this machine's MEM GiB; lower --units, --seeds, --popsize, --n-envs or --n-steps"),
    ("test --study one --storage sqlite:///studies.db --out .", "ermrl test: error: test.partial holds files that "
     "ermrl did not write there (notes.txt); move them away, then rerun"),
    ("test --study s --trial -1", "ermrl test: error: --trial must be a trial number >= 0, got -1"),
    ("test --study s --auc-steps 0", "ermrl test: error: --auc-steps must be >= 1, got 0"),
    ("test --study s --agents-per-run 0", "ermrl test: error: --agents-per-run must be >= 1, got 0"),
    ("test --study s --baseline-store afile", "ermrl test: error: --baseline-store afile is a file, not a folder; "
                                              "give a folder path (it is created if missing)"),
    ("test --study s --env Nope-v1", "ermrl test: error: unknown env id 'Nope-v1': Gymnasium has no 'Nope-v1'; did "
                                     "you mean Hopper-v5, Hopper-v4, Hopper-v3?"),
    (f"test --study one --storage {SQLITE} --trial 7", "ermrl test: error: trial 7 of study 'one' is not a completed "
                                                       "trial; completed trials include 0"),
    (f"test --study empty --storage {SQLITE}", "ermrl test: error: study 'empty' has no completed trial yet; run "
                                               "`ermrl evolve` first"),
    ("report --study nope", "ermrl report: error: no study 'nope': runs/nope/study.db does not exist; run `ermrl "
                            "evolve` first or pass --storage/--out"),
    ("report --study nope --out afile", "ermrl report: error: --out afile is a file, not a folder; give a folder "
                                        "path (it is created if missing)"),
    # -- plot, baselines ------------------------------------------------------------------------------------
    ("plot curves_bad --out fig.png", "ermrl plot: error: curves_bad/curves.csv is not a curves file written by ermrl "
                                      "(KeyError: 'mean_return_100'); rerun the command that wrote it"),
    ("plot nothere --out fig.png", "ermrl plot: error: nothere has no curves.csv; give folders written by `ermrl "
                                   "train` or `ermrl test`"),
    ("plot curves_bad", "ermrl plot: error: the following arguments are required: --out; see `ermrl plot --help`"),
    ("baselines --env Nope-v0", "ermrl baselines: error: unknown env id 'Nope-v0': Gymnasium has no 'Nope-v0'; did "
                                "you mean Hopper-v5, Hopper-v4, Hopper-v3?"),
    ("baselines --env CartPole-v1 --random-episodes 0", "ermrl baselines: error: --seeds and --random-episodes must "
                                                        "be >= 1, got 3 and 0"),
    ("baselines --env CartPole-v1 --table adir", "ermrl baselines: error: baselines table adir is a folder; give a "
                                                 "file path such as adir/baselines.json"),
    ("baselines --env CartPole-v1 --table afile", "ermrl baselines: error: baselines table afile is damaged "
                                                  "(Expecting value: line 1 column 1 (char 0)); fix it or delete it "
                                                  "and rerun `ermrl baselines`"),
    # -- experiment -----------------------------------------------------------------------------------------
    ("experiment run partial-observabilty", "ermrl experiment: error: unknown experiment 'partial-observabilty'; did "
                                            "you mean partial-observability? (`ermrl experiment list` names them all)"),
    ("experiment run partial-observability --test-agents-per-run 0",
     "ermrl experiment: error: --test-agents-per-run must be >= 1, got 0"),
    ("experiment run partial-observability --scale huge",
     "ermrl experiment: error: argument --scale: invalid choice: 'huge' (choose from 'smoke', 'small', 'medium', "
     "'converged', 'paper'); see `ermrl experiment run --help`"),
    ("experiment run partial-observability --only cartpole1res",
     "ermrl experiment: error: experiment partial-observability has no study 'cartpole1res'; its studies: "
     "cartpole-1res, cartpole-2res, lunarlander-1res, lunarlander-2res, pendulum-1res, pendulum-2res; did you mean "
     "cartpole-1res?"),
    ("experiment run generalization-morphology --scale smoke --baselines afile",
     "ermrl experiment: error: baselines table afile is damaged (Expecting value: line 1 column 1 (char 0)); fix it "
     "or delete it and rerun `ermrl baselines`"),
    ("experiment run partial-observability --out afile", "ermrl experiment: error: --out afile is a file, not a "
                                                         "folder; give a folder path (it is created if missing)"),
    ("experiment run partial-observability --baseline-store afile/models",
     "ermrl experiment: error: --baseline-store afile/models: its parent afile is a file, not a folder; give a "
     "folder path (it is created if missing)"),
    # -- analyze --------------------------------------------------------------------------------------------
    ("analyze hp-map nope --out fig.png", "ermrl analyze: error: no study 'nope': runs/nope/study.db does not exist; "
                                          "run `ermrl evolve --study nope` first or pass --storage"),
    (f"analyze hp-map empty --storage {SQLITE} --out fig.png",
     "ermrl analyze: error: study 'empty' has no completed trial; run `ermrl evolve --study empty` until one "
     "completes"),
    ("analyze probe --env CartPole-v1 --out fig.png", "ermrl analyze: error: probe needs a NoVel env id whose "
                                                      "velocities are deleted, got 'CartPole-v1'; use "
                                                      "'CartPoleNoVel-v1'"),
    ("analyze probe --env Nope-v1 --out fig.png", "ermrl analyze: error: unknown env id 'Nope-v1': Gymnasium has no "
                                                  "'Nope-v1'; did you mean Hopper-v5, Hopper-v4, Hopper-v3?"),
    ("analyze probe --env CartPoleNoVel-v1 --phi nan 0.5 1 --out fig.png",
     "ermrl analyze: error: --phi nan 0.5 1: SR and ISS must be in (0, 1e+06] and LR (the leak rate) in (0, 1]"),
    ("analyze probe --env CartPoleNoVel-v1 --phi 1e300 0.5 1 --out fig.png",
     "ermrl analyze: error: --phi 1e+300 0.5 1: SR and ISS must be in (0, 1e+06] and LR (the leak rate) in (0, 1]"),
    ("analyze probe --env CartPoleNoVel-v1 --units 100000000000000000000 --out fig.png",
     "ermrl analyze: error: --units must be <= 10,000, got 100000000000000000000"),
    ("baselines --env CartPole-v1 --seeds 100000000000000000000", "ermrl baselines: error: the PPO baseline needs at "
     "least MEM GiB of memory (100000000000000000000 agents, 1 envs × 2048 steps per rollout), more than this "
     "machine's MEM GiB; lower --units, --seeds, --popsize, --n-envs or --n-steps"),
    ("baselines --env CartPole-v1 --random-episodes 100000000000000000000", "ermrl baselines: error: "
     "--random-episodes must be <= 1,000,000, got 100000000000000000000"),
    ("analyze probe --env CartPoleNoVel-v1 --phi 1 0.5 --out fig.png",
     "ermrl analyze: error: argument --phi: expected 3 arguments; see `ermrl analyze probe --help`"),
    (f"analyze probe --env CartPoleNoVel-v1 --study one --storage {SQLITE} --units 50 --out fig.png",
     "ermrl analyze: error: study 'one' evolved 100-unit reservoirs; pass --units 100"),
    ("analyze probe --env CartPoleNoVel-v1 --out afile/fig.png", "ermrl analyze: error: --out afile/fig.png: its "
                                                                 "parent afile is a file, not a folder; give a path "
                                                                 "in a folder"),
    ("analyze context nothere", "ermrl analyze: error: nothere does not exist; give a run folder or a saved agent "
                                "file (.npz)"),
    ("analyze context adir", "ermrl analyze: error: adir holds no saved agent; train with --save-agents (the "
                             "default) first"),
    ("analyze context badagent.npz --units 0", "ermrl analyze: error: --units must be >= 1, got 0"),
    ("analyze fft badagent.npz --out fig.png --seed -1", "ermrl analyze: error: --seed must be >= 0, got -1"),
    ("analyze fft badagent.npz --out fig.png",
     "ermrl analyze: error: badagent.npz is not a readable ermrl agent file (KeyError: 'meta'); it "
     "is damaged or was not written by ermrl: retrain, or load another agent"),
    ("analyze evaluate badagent.npz --episodes 0", "ermrl analyze: error: --episodes must be >= 1, got 0"),
    ("analyze evaluate badagent.npz --seed -1", "ermrl analyze: error: --seed must be >= 0, got -1"),
    ("analyze evaluate badagent.npz --max-steps 0", "ermrl analyze: error: --max-steps must be >= 1, got 0"),
    ("analyze evaluate adir --out adir", "ermrl analyze: error: --out adir is a folder; give a file path such as "
                                         "adir/evaluation.md"),
    ("analyze evaluate badagent.npz",
     "ermrl analyze: error: badagent.npz is not a readable ermrl agent file (KeyError: 'meta'); it "
     "is damaged or was not written by ermrl: retrain, or load another agent"),
    # -- video, dashboard, the command itself ----------------------------------------------------------------
    ("video", "ermrl video: error: give a run folder (ermrl video RUN) or an agent file (--agent FILE)"),
    ("video nothere", "ermrl video: error: run folder nothere does not exist; give a folder written by `ermrl train` "
                      "or `ermrl test`"),
    ("video afile", "ermrl video: error: afile is a file, not a run folder; give the folder, or the agent file as "
                    "--agent afile"),
    ("video --agent badagent.npz --episodes 0", "ermrl video: error: --episodes must be >= 1, got 0"),
    ("video --agent badagent.npz --fps 0", "ermrl video: error: --fps must be between 0.1 and 1000 frames per "
                                           "second, got 0; or leave it out for the env's rate"),
    ("video --agent badagent.npz --fps 1e-300", "ermrl video: error: --fps must be between 0.1 and 1000 frames per "
                                                "second, got 1e-300; or leave it out for the env's rate"),
    ("video --agent badagent.npz --fps 1e300", "ermrl video: error: --fps must be between 0.1 and 1000 frames per "
                                               "second, got 1e+300; or leave it out for the env's rate"),
    ("video --agent badagent.npz --episodes 1000000", "ermrl video: error: --episodes must be <= 100 (their frames "
                                                      "are held until the file is written), got 1000000"),
    ("video --agent ''", "ermrl video: error: argument --agent: is an empty path; give a path, or leave the option "
                         "out for its default; see `ermrl video --help`"),
    ("video --agent badagent.npz --out clip.avi", "ermrl video: error: video file clip.avi must end in .mp4 or .gif"),
    ("dashboard --study nope", "ermrl dashboard: error: no study 'nope': runs/nope/study.db does not exist; run "
                               "`ermrl evolve` first or pass --storage/--out"),
    ("dashboard --study one --port 70000", "ermrl dashboard: error: --port 70000 is not a port; give 1..65535, or 0 "
                                           "for any free port"),
    ("", "ermrl: error: the following arguments are required: COMMAND; see `ermrl --help`"),
    ("trian --units 5", "ermrl: error: argument COMMAND: invalid choice: 'trian' (choose from 'train', 'evolve', "
                        "'select', 'test', 'report', 'plot', 'baselines', 'experiment', 'reproduce', 'analyze', "
                        "'compare', 'test-progress', 'convergence', 'video', 'dashboard'); see `ermrl --help`"),
    # -- compare, test-progress, reproduce: the files they read, the steps they name ------------------------
    ("compare a=missing.json", "ermrl compare: error: missing.json is not a file; give a test phase's or an `ermrl "
                               "train` run's summary.json"),
    ("compare a=studies.db=x", "ermrl compare: error: studies.db=x is not a file; give a test phase's or an `ermrl "
                               "train` run's summary.json"),
    ("compare nolabel.json", "ermrl compare: error: argument LABEL=SUMMARY.json: 'nolabel.json' is not "
                             "LABEL=SUMMARY.json (e.g. '25 units=.../test/summary.json'); see `ermrl compare --help`"),
    ("test-progress runs/nope", "ermrl test-progress: error: runs/nope.partial is not a folder; give an unfinished "
                                "test phase's OUT or OUT.partial folder"),
    ("reproduce --dry-run C0", "ermrl reproduce: error: unknown step or claim 'C0'; steps: "
     + " ".join(STEPS) + "; claims: " + " ".join(f"C{i}" for i in range(1, 18))),
    # -- the learning rate's flags of older versions: refused, naming the flag of today ----------------------
    ("train --ppo-lr 1e-4", "ermrl train: error: --ppo-lr is now --learning-rate (PPO's learning rate); see `ermrl "
                            "train --help`"),
    ("evolve --ppo-lr 1e-4", "ermrl evolve: error: --ppo-lr is now --learning-rate (PPO's learning rate); see `ermrl "
                             "evolve --help`"),
    ("baselines --env CartPole-v1 --ppo-lr 1e-4", "ermrl baselines: error: --ppo-lr is now --learning-rate (PPO's "
                                                  "learning rate); see `ermrl baselines --help`"),
    ("test --study s --ermrl-lr 3e-4 1e-4", "ermrl test: error: --ermrl-lr is now --learning-rate (the ER-MRL agents' "
                                            "learning rates); see `ermrl test --help`"),
    ("test --study s --ppo-lr 3e-4", "ermrl test: error: --ppo-lr is now --baseline-learning-rate (the PPO baselines' "
                                     "learning rate); see `ermrl test --help`"),
    ("experiment run partial-observability --test-lrs 1e-4", "ermrl experiment: error: --test-lrs is now "
     "--test-learning-rates (ER-MRL's learning rates in every test phase); see `ermrl experiment run --help`"),
    # -- --stop-after: a duration with units ------------------------------------------------------------------
    ("evolve --stop-after 90", "ermrl evolve: error: argument --stop-after: must be a duration with units such as "
                               "2h30m, 90m or 45s, got '90'; see `ermrl evolve --help`"),
    ("evolve --stop-after 0s", "ermrl evolve: error: argument --stop-after: must be longer than 0 s and at most a year "
                               "(8784h), got '0s'; see `ermrl evolve --help`"),
    ("experiment run locomotion --stop-after 30m2h", "ermrl experiment: error: argument --stop-after: must be a "
     "duration with units such as 2h30m, 90m or 45s, got '30m2h'; see `ermrl experiment run --help`"),
    ("reproduce h2_converged --stop-after 9999h", "ermrl reproduce: error: argument --stop-after: must be longer than "
                                                  "0 s and at most a year (8784h), got '9999h'; see `ermrl reproduce "
                                                  "--help`"),
]
