"""The type stubs describe the compiled module: same names, same parameters and defaults."""

import ast
import inspect
from pathlib import Path

import msgp
from msgp import _msgp

STUB = Path(msgp.__file__).with_name("_msgp.pyi")


def stub_signature(fn: ast.FunctionDef) -> str:
    """`(a, b=1, *, c=None)` from a stub definition, without annotations."""
    a = fn.args
    names = [x.arg for x in a.posonlyargs + a.args]
    defaults = [None] * (len(names) - len(a.defaults)) + list(a.defaults)
    parts = [n if d is None else f"{n}={ast.unparse(d)}" for n, d in zip(names, defaults)]
    if a.kwonlyargs:
        parts.append("*")
        for x, d in zip(a.kwonlyargs, a.kw_defaults):
            parts.append(x.arg if d is None else f"{x.arg}={ast.unparse(d)}")
    return ("(" + ", ".join(parts) + ")").replace("'", '"')


def runtime_signature(obj) -> str:
    sig = inspect.signature(obj)
    params = [p.replace(annotation=inspect.Parameter.empty) for p in sig.parameters.values()]
    text = str(sig.replace(parameters=params, return_annotation=inspect.Signature.empty))
    return text.replace("'", '"').replace(", /", "")


def test_stubs_match_the_module():
    tree = ast.parse(STUB.read_text())
    stubbed = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            stubbed.add(node.name)
            assert stub_signature(node) == runtime_signature(getattr(_msgp, node.name)), node.name
        elif isinstance(node, ast.ClassDef):
            stubbed.add(node.name)
            cls = getattr(_msgp, node.name)
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and not item.name.startswith("__"):
                    assert hasattr(cls, item.name), f"{node.name}.{item.name}"
                    is_property = any(ast.unparse(d) == "property" for d in item.decorator_list)
                    if not is_property:
                        assert stub_signature(item) == runtime_signature(getattr(cls, item.name)), f"{node.name}.{item.name}"
                elif isinstance(item, ast.FunctionDef) and item.name == "__init__":
                    init = stub_signature(item).replace("(self, ", "(")
                    assert init == runtime_signature(cls), node.name
    public = {n for n in dir(_msgp) if not n.startswith("_")}
    assert public == stubbed, public ^ stubbed
    # the package re-exports the compiled module but for the pieces msgp.sweep and msgp.gym
    # build on
    sweep_parts = {"table1_plan", "table1_unit", "table1_report", "update_results_section",
                   "figure4_plan", "figure4_budget", "figure4_unit", "figure4_report",
                   "learn_on_plant"}
    assert set(msgp.__all__) - {"__version__", "sweep"} == stubbed - sweep_parts
    assert (STUB.parent / "py.typed").is_file()
