"""Local Sphinx extension for the drake-abs API reference (``docs/conf.py``).

Three things plain autodoc does not do for this package:

1. ``.. pydrake_system::``: Drake's directive for a LeafSystem's ports (its docstrings use it
   the way Drake's own do). Rendered here as a small block diagram: input ports on the left,
   output ports on the right.
2. ``TemplateSystem.define`` LeafSystems: ``LcsPlant`` is ``LcsPlant_[float]``, a class whose
   ``__init__`` is ``(*args, **kwargs)`` and whose ``__name__`` is the mangled
   ``LcsPlant_𝓣float𝓤``. For the build, the class is named ``LcsPlant`` (so it is documented
   once, under that name, not as an alias), its signature is taken from ``_construct`` (the
   real constructor, as ``TemplateSystem`` calls it), and a note names the scalar-type
   template. The package's code is not changed.
3. References to re-exported names: ``drake_abs.LCS`` (or ``LCS`` inside a module that imports
   it) resolves to the entry at the defining module, ``drake_abs.contact.lcs.LCS``, since each
   object is documented once, where it is defined.
"""

from __future__ import annotations

import importlib
import inspect
import re
from typing import Any

import yaml
from docutils import nodes
from docutils.parsers.rst import Directive
from sphinx.application import Sphinx


# -- 1. pydrake_system ----------------------------------------------------------------------------
class PydrakeSystemDirective(Directive):
    """``.. pydrake_system::`` with a YAML body: ``name``, ``input_ports``, ``output_ports``."""

    has_content = True

    def run(self) -> list[nodes.Node]:
        try:
            spec = yaml.safe_load("\n".join(self.content)) or {}
        except yaml.YAMLError as exc:
            raise self.error(f"pydrake_system: invalid YAML: {exc}") from exc
        name = str(spec.get("name", "System"))
        inputs = [str(p) for p in spec.get("input_ports", []) or []]
        outputs = [str(p) for p in spec.get("output_ports", []) or []]
        text = _block_diagram(name, inputs, outputs)
        block = nodes.literal_block(text, text)
        block["language"] = "none"
        block["classes"].append("pydrake-system")
        return [block]


def _block_diagram(name: str, inputs: list[str], outputs: list[str]) -> str:
    rows = max(len(inputs), len(outputs), 1)
    left = max((len(p) for p in inputs), default=0)
    width = len(name) + 4
    lines = [" " * (left + 5) + "+" + "-" * width + "+"]
    for i in range(rows):
        inp = f"{inputs[i]:>{left}} --> " if i < len(inputs) else " " * (left + 5)
        label = name if i == (rows - 1) // 2 else ""
        out = f" --> {outputs[i]}" if i < len(outputs) else ""
        lines.append(f"{inp}|  {label:<{width - 2}}|{out}".rstrip())
    lines.append(" " * (left + 5) + "+" + "-" * width + "+")
    return "\n".join(lines)


# -- 2. TemplateSystem classes ----------------------------------------------------------------
#: class -> its template's name, for the ``Xxx = Xxx_[None]`` classes of the Drake layers.
_TEMPLATE_CLASSES: dict[type, str] = {}


def _register_template_systems(app: Sphinx) -> None:
    """Name each ``Xxx = Xxx_[None]`` class ``Xxx`` (for this build only).

    ``TemplateSystem`` names the instantiation ``Xxx_𝓣float𝓤``; autodoc would then show
    ``Xxx`` as an "alias of Xxx_𝓣float𝓤" and document the class under the mangled name. Giving
    the class its public name documents it once, as ``Xxx``, like any other class.
    """
    import pkgutil

    from pydrake.systems.scalar_conversion import TemplateSystem

    for package in ("drake_abs.systems", "drake_abs.diagrams"):
        pkg = importlib.import_module(package)
        for info in pkgutil.iter_modules(pkg.__path__):
            if info.name.startswith("_"):
                continue
            module = importlib.import_module(f"{package}.{info.name}")
            for attr, value in list(vars(module).items()):
                template = vars(module).get(f"{attr}_")
                if not (inspect.isclass(value) and isinstance(template, TemplateSystem)):
                    continue
                if value.__module__ != module.__name__ or "𝓣" not in value.__name__:
                    continue
                _TEMPLATE_CLASSES[value] = f"{attr}_"
                value.__name__ = attr
                value.__qualname__ = attr


def _template_system_name(obj: Any) -> str | None:
    """``"LcsPlant_"`` for ``LcsPlant`` (``LcsPlant_[float]``), else None."""
    try:
        return _TEMPLATE_CLASSES.get(obj)
    except TypeError:  # unhashable
        return None


def _process_signature(app, what, name, obj, options, signature, return_annotation):
    changed = False
    if what == "class" and _template_system_name(obj) is not None:
        try:
            sig = inspect.signature(obj._construct, eval_str=True)
        except Exception:  # an annotation only importable under TYPE_CHECKING
            sig = inspect.signature(obj._construct)
        params = list(sig.parameters.values())[1:]  # drop self
        sig = sig.replace(parameters=params, return_annotation=inspect.Signature.empty)
        signature, return_annotation, changed = str(sig), None, True
    if signature and "<factory>" in signature:
        # A dataclass field with a default_factory: inspect prints ``<factory>``, which is no
        # Python expression, and Sphinx would then fail to parse the whole signature.
        signature, changed = signature.replace("<factory>", "..."), True
    return (signature, return_annotation) if changed else None


def _skip_member(app, what, name, obj, skip, options):
    # TemplateSystem adds pydrake's own ToScalarType/ToAutoDiffXd/... to each instantiation:
    # Drake documents those, not this package.
    if str(getattr(obj, "__module__", "") or "").startswith("pydrake"):
        return True
    # ... and binds each instantiation in its module under the mangled name too
    # (``LcsPlant_𝓣float𝓤``): the class is documented once, as ``LcsPlant``.
    if "𝓣" in name:
        return True
    return None


def _process_docstring(app, what, name, obj, options, lines):
    template = _template_system_name(obj) if what == "class" else None
    if template is None:
        return
    short = name.rsplit(".", 1)[-1]
    lines.extend(
        [
            "",
            f".. note:: ``{short}`` is ``{template}[float]``: a Drake ``TemplateSystem``; "
            f"``{template}[AutoDiffXd]`` is the same system under automatic differentiation "
            "(``ToAutoDiffXd()`` converts one into the other).",
            "",
        ]
    )


# -- 3. re-exported names ---------------------------------------------------------------------
def _import_target(target: str, module: str | None, cls: str | None = None) -> Any:
    """The object ``target`` names: inside ``module.cls``, inside ``module``, or absolute."""
    candidates = []
    if module and cls:
        candidates.append(f"{module}.{cls}.{target}")
    if module:
        candidates.append(f"{module}.{target}")
    candidates.append(target)
    for cand in candidates:
        parts = cand.split(".")
        for i in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:i]))
            except Exception:
                continue
            try:
                for attr in parts[i:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            return obj
    return None


def _canonical(target: str, module: str | None, cls: str | None = None) -> str | None:
    """The defining module's dotted name for ``target``, when it differs from ``target``."""
    # Walk from the longest prefix that names a class or function, keep what follows it.
    parts = target.split(".")
    for i in range(len(parts), 0, -1):
        obj = _import_target(".".join(parts[:i]), module, cls)
        if obj is None:
            continue
        mod = getattr(obj, "__module__", None)
        qual = getattr(obj, "__qualname__", None)
        if inspect.ismodule(obj):
            canon = obj.__name__
        elif isinstance(mod, str) and isinstance(qual, str) and "<locals>" not in qual:
            canon = f"{mod}.{qual}"
        else:  # a value (a class attribute's tuple, say): name it through its owner
            continue
        rest = parts[i:]
        full = ".".join([canon, *rest])
        return full if full != target else None
    return None


# ``drake_abs.systems.lcs_plant.LcsPlant_𝓣float𝓤`` (a type hint's class; the 𝓣/𝓤 can arrive
# NFKC-normalised to T/U) is documented as ``drake_abs.systems.lcs_plant.LcsPlant``.
_TEMPLATE_INSTANCE = re.compile(
    r"^(?P<mod>.+)\.(?P<name>\w+?)_(?:𝓣|T)(?:float|AutoDiffXd|Expression)(?:𝓤|U)$"
)


def _missing_reference(app: Sphinx, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    if not target or target.startswith(("numpy", "np.", "scipy", "pydrake")):
        return None
    match = _TEMPLATE_INSTANCE.match(target)
    if match and target.startswith("drake_abs"):
        canon = f"{match['mod']}.{match['name']}"
        shown = contnode.astext()
        if "𝓣" in shown or shown.endswith("U"):  # the mangled name: show the documented one
            if isinstance(contnode, nodes.Text):
                contnode = nodes.Text(match["name"])
            else:
                contnode = contnode.__class__("", match["name"], classes=contnode["classes"])
    else:
        canon = _canonical(target, node.get("py:module"), node.get("py:class"))
    if canon is None or not canon.startswith("drake_abs"):
        return None
    domain = env.domains["py"]
    node = node.deepcopy()
    node["reftarget"] = canon
    return domain.resolve_xref(
        env, node["refdoc"], app.builder, node["reftype"], canon, node, contnode
    )


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_directive("pydrake_system", PydrakeSystemDirective)
    app.connect("builder-inited", _register_template_systems)
    app.connect("autodoc-process-signature", _process_signature)
    app.connect("autodoc-process-docstring", _process_docstring)
    app.connect("autodoc-skip-member", _skip_member)
    app.connect("missing-reference", _missing_reference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
