"""The action templates (paper eq. 1), one module each, and their registry ``TEMPLATES``.

What it does: ``TEMPLATES`` maps the name a plan uses (``move_to``, ``grasp``, ``place``,
``push``) to its template class (``base.Template``); the task checks plans against it and the
rollout instantiates one template object per name for the N copies.
What it doesn't: implement a template (see ``move_to``, ``grasp``, ``place``, ``push``, and
``manipulate`` for the steps grasp and place share).

Adding a template: write a module with a ``Template`` subclass and add it below.
"""

from __future__ import annotations

from realize.realization.actions.base import Template
from realize.realization.actions.grasp import Grasp
from realize.realization.actions.move_to import MoveTo
from realize.realization.actions.place import Place
from realize.realization.actions.push import Push

TEMPLATES: dict[str, type[Template]] = {cls.name: cls for cls in (MoveTo, Grasp, Place, Push)}
