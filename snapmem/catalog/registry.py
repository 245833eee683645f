"""The scene registry: named scenes with documented parameters, and :func:`build_scene`.

A scene is registered once with its parameters (name, default, unit, allowed range, doc) and a
builder that turns validated parameters into a :class:`~snapmem.model.scene.Scene`. A scene with a
``material`` parameter also takes the parameters the chosen law declares (those the scene does not
declare itself, with the law's defaults), so a law registered with
:func:`snapmem.model.materials.register_law` is usable by name with no edit here, and any law
instance by ``build_scene(name, law=...)``.
"""

from __future__ import annotations

from typing import Callable

from snapmem.errors import SnapmemError
from snapmem.model.materials import LAWS, Law, law_class
from snapmem.model.parameters import Parameter
from snapmem.model.scene import Scene

__all__ = ["Parameter", "SceneSpec", "SCENES", "register", "get_spec", "build_scene"]


def _law_parameter_names() -> set:
    """Names of the parameters of every registered law, and ``mu`` (the scenes' shear modulus)."""
    return {"mu"}.union(*(names for _, names in LAWS.values()))


class SceneSpec:
    """A named scene: its parameters and the builder that makes a Scene from them.

    Parameters
    ----------
    name, doc : str
    parameters : tuple of Parameter
        The scene's own parameters, in the order they are listed and recorded.
    builder : callable (params: dict, with_loads: tuple) -> Scene
        ``params`` are the resolved parameters; with ``build(law=...)`` its ``material`` is that
        Law instance.
    """

    def __init__(self, name: str, doc: str, parameters: tuple, builder: Callable[..., Scene]):
        self.name, self.doc, self.declared, self.builder = name, doc, tuple(parameters), builder

    def __repr__(self):
        return f"SceneSpec({self.name!r}, {self.doc!r})"

    @property
    def takes_material(self) -> bool:
        return any(p.name == "material" for p in self.declared)

    @property
    def parameters(self) -> tuple:
        """The declared parameters, then (scenes with a material) those of registered laws the scene
        does not declare, each documented with its law's name."""
        if not self.takes_material:
            return self.declared
        return self.declared + tuple(_law_extras(self.declared, LAWS))

    def known(self, material) -> dict:
        """name -> Parameter accepted with ``material`` (a law name, or a Law instance: then none of
        the laws' parameters)."""
        known = {p.name: p for p in self.declared}
        if not self.takes_material:
            return known
        if isinstance(material, Law):
            law_names = _law_parameter_names()
            return {name: p for name, p in known.items() if name not in law_names}
        chosen = law_class(material)
        known.update({p.name: p for p in chosen.parameters if p.name not in known})
        return known

    def resolve(self, law: Law | None = None, **values) -> dict:
        """Defaults updated by ``values``, each checked; unknown names are an error.

        Parameters
        ----------
        law : Law, optional
            The scene's law as an instance (then neither ``material`` nor a law parameter may be
            set); it is the ``material`` of the result.
        """
        declared = {p.name: p for p in self.declared}
        if law is not None:
            _check_law_instance(self, law, values)
            material = law
        elif self.takes_material:
            material = values.get("material", declared["material"].default)
        else:
            material = None
        known = self.known(material)                  # an unknown law name fails here
        for key in values:
            if key in known:
                continue
            if law is not None and key in _law_parameter_names():
                raise SnapmemError(f"parameter {key!r}: the law is given as an instance (law = {law!r}); "
                                   "set its parameters there")
            raise SnapmemError(f"parameter {key!r}: scene {self.name!r} has no such parameter; "
                               f"it has {', '.join(p.name for p in self.parameters)}")
        for name, p in known.items():
            for other in p.excludes:
                if name in values and other in values:
                    raise SnapmemError(f"{other} = {values[other]} and {name} = {values[name]}: "
                                       "set one of them, not both")
        return {name: material if name == "material" else p.check(values.get(name, p.default))
                for name, p in known.items()}

    def build(self, with_loads: tuple = (), law: Law | None = None, **values) -> Scene:
        """Build the scene. ``with_loads`` names loads (e.g. 'voltage') whose terms are included
        even when their value is zero (for continuation in that load); ``law`` is the scene's law
        as an instance (instead of ``material`` and its parameters)."""
        params = self.resolve(law, **values)
        return self.builder(params, tuple(with_loads))


def _check_law_instance(spec: SceneSpec, law, values: dict) -> None:
    if not spec.takes_material:
        raise SnapmemError(f"law = {law!r}: scene {spec.name!r} has no material")
    if not isinstance(law, Law):
        raise SnapmemError(f"law = {law!r}: must be an instance of a subclass of snapmem.Law")
    if "material" in values:
        raise SnapmemError(f"material = {values['material']!r} and law = {law!r}: set one of them, not both")


def _law_extras(declared: tuple, laws: dict):
    """Parameters of the registered laws not among ``declared``, one per name, documented with the
    names of the laws that take it."""
    seen = {p.name for p in declared}
    for name, (cls, _) in laws.items():
        for p in cls.parameters:
            if p.name not in seen:
                seen.add(p.name)
                yield Parameter(**{**p.__dict__, "doc": f"{name}: {p.doc}"})


SCENES: dict[str, SceneSpec] = {}


def register(spec: SceneSpec) -> SceneSpec:
    """Add a scene to the registry (the one place a new scene is made known)."""
    SCENES[spec.name] = spec
    return spec


def get_spec(name: str) -> SceneSpec:
    if name not in SCENES:
        raise SnapmemError(f"scene {name!r}: unknown; available: {', '.join(SCENES)}")
    return SCENES[name]


def build_scene(name: str, with_loads: tuple = (), law: Law | None = None, **params) -> Scene:
    """Build the registered scene ``name`` with parameters overriding its defaults.

    Parameters
    ----------
    name : str
    with_loads : tuple of str
        Loads whose terms are included even at zero (for continuation in them).
    law : Law, optional
        The scene's hyperelastic law as an instance (any subclass of snapmem.Law), instead of
        ``material=NAME`` and that law's parameters.
    **params
        Scene parameters (``snapmem scenes`` lists them), as numbers or text.

    Examples
    --------
    >>> scene = build_scene("balloon", nodes=101, E_hat=0.1538)
    >>> scene = build_scene("balloon", law=NeoHookean(mu=1.0))
    """
    return get_spec(name).build(with_loads, law, **params)
