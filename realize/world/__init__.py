"""The world, as data: scene geometry and the state of one copy of the scene.

Modules: ``geometry`` (``GeometryCfg``, the Hydra ``scene`` group, and the boxes it makes),
``state`` (``SceneState``: robot joints, gripper and objects of one copy, as JSON).
What it doesn't: simulate (``realize.scene``), or know tasks, plans or regions (``realize.tasks``).
"""
