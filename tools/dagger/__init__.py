"""DAgger (Ross, Gordon and Bagnell 2011) on ``rbc/Drive-v0``: ``rbc dagger``, and its behavioral-cloning baseline.

Start with behavioral cloning on the autopilot's driving, then rounds: the learner drives (the expert mixed in
per step with probability beta, decaying), the autopilot labels every visited frame with its pure-pursuit
steering (``info["expert_action"]``), the rounds' frames are aggregated, the learner is retrained from scratch on
them with ``rbc train``'s pipeline and exported to ONNX, and each round's model is scored on unseen generated
worlds and the built-in tracks exactly as ``rbc eval`` scores a model. :mod:`tools.dagger.loop` has the rounds,
:mod:`~tools.dagger.rollout` the data, :mod:`~tools.dagger.mixing` the mixing and labelling (a Gymnasium
wrapper) with :mod:`~tools.dagger.beta`'s schedules, :mod:`~tools.dagger.scoring` the evaluation,
:mod:`~tools.dagger.summary` the rounds' table, :mod:`~tools.dagger.report` the comparison with behavioral cloning
at equal expert frames; docs/python.md the measurement.

Why a loop of our own and not the ``imitation`` library's ``SimpleDAggerTrainer`` (imitation 1.0.1,
the newest on the package index):

* Installing it would break this project's environment. ``pip install --dry-run imitation`` resolves 53 packages
  and pins ``gymnasium~=0.29`` and ``stable-baselines3~=2.2.1``: it would downgrade gymnasium 1.4.0 to 0.29.1 and
  SB3 2.9.2 to 2.2.1 (torch 2.13.0 stays). ``rbc/Drive-v0`` is written for gymnasium >= 1.0 (the ``gym`` extra;
  ``gym.make_vec``, which its tests use, came with 1.0), and the rest (sacred, optuna, datasets,
  pyarrow, tensorboard, pygame, ...) is weight for a loop this small. Installed without its dependencies
  (requirements-imitation.txt), its BC and SimpleDAgger do run on ``rbc/Drive-v0``
  (tests/test_envs_imitation.py), with datasets and pyarrow still in tow for DAgger's saved rounds.
* Its learner is not ours. ``imitation.algorithms.bc.BC`` fits an SB3 ``ActorCriticPolicy`` (its own CNN, a
  Gaussian's log-likelihood) on raw observations. Our learner is the paper's network trained by ``rbc train``:
  zero-steer balancing, the augmentations, the crop and resize of its preprocessing contract, and an ONNX export
  that carries that contract, which drive_server, ``OnnxPolicy`` and ``rbc eval`` need. Neither the pipeline nor
  the export exists there; scoring an SB3 policy would not be scoring the model this project deploys.
* Its expert acts on observations (``expert_policy.predict(obs)``); ours needs the simulator's state (pure
  pursuit of the driving line), which the environment hands over as ``info["expert_action"]``: the library
  would need an expert wrapper reaching into the environment.
* Its rounds fine-tune one policy and keep demonstrations as ``.npz`` arrays of raw frames (153,600 bytes a
  frame, all loaded into memory every round); ours retrain from scratch (each round's model a function of its
  data alone) and keep recordings ``rbc train`` reads unchanged, the wire's JPEGs, about 10 kB a frame.

What we keep of it: the algorithm as it implements it (per-step mixing, each step the expert's action with
probability beta, and every visited state labelled by the expert whoever drove), its round structure and its
shape: a beta schedule object (:class:`~tools.dagger.beta.BetaSchedule`) and the mixing as a wrapper of the
environment (:class:`~tools.dagger.mixing.ExpertMixing`, as its ``InteractiveTrajectoryCollector`` wraps a
VecEnv), reading the expert from the environment's public ``info["expert_action"]``.
"""

from __future__ import annotations

from tools.dagger.config import DaggerConfig

__all__ = ["DaggerConfig"]
