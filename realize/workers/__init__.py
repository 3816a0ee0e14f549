"""Rollout workers: a run's copies cut into shards (one PhysX scene each), held by this process,
local worker processes or Ray actors.

Modules: ``pool`` (``open_pool``, the entry point), ``worker`` (what one worker holds, whatever
runs it), ``realizers`` (the one place a shard's scene and plan realizers are built), ``blocks``
(a batch's rows dealt per worker, results joined; the shards themselves are
``realize.scene.shards``), ``process`` (local worker processes), ``ray_pool`` (Ray actors),
``replicas`` (a robust search's R perturbed worlds per sample), ``errors`` (the error a run stops
with when its workers cannot go on). Their settings are ``realize.spec.workers_settings``.

What it doesn't: choose what to simulate (``realize.run.loop`` hands it each batch)."""
