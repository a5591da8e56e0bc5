"""The type stubs (hgs/__init__.pyi, clip.pyi, sam.pyi) describe what the package has: every function, class and
class member they declare exists at run time, and every public name of the package is declared."""

import ast
import os

import hgs

STUBS = os.path.dirname(hgs.__file__)


def declared(path):
    tree = ast.parse(open(path).read())
    funcs, classes = set(), {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            funcs.add(node.name)
        elif isinstance(node, ast.ClassDef):
            members = set()
            for b in node.body:
                if isinstance(b, ast.FunctionDef) and not b.name.startswith("__"):
                    members.add(b.name)
                elif isinstance(b, ast.AnnAssign):
                    members.add(b.target.id)
            classes[node.name] = members
    return funcs, classes


def check(module, path, instances={}):
    funcs, classes = declared(path)
    for f in funcs:
        assert callable(getattr(module, f, None)), f"{path}: {f} is not in {module.__name__}"
    for c, members in classes.items():
        cls = getattr(module, c, None)
        assert cls is not None, f"{path}: class {c} is not in {module.__name__}"
        obj = instances.get(c, cls)  # pure-Python classes set their attributes on the instance
        for m in members:
            if c == "Model" and m == "train_stats":  # set on the instance by hgs.train
                continue
            assert hasattr(obj, m), f"{path}: {c}.{m} does not exist"
    return funcs | set(classes)


def test_stubs_match_the_package(hybrid_model, scene):
    answer = hgs.query(hybrid_model, scene, next(iter(scene.text_embeddings)))
    names = check(hgs, os.path.join(STUBS, "__init__.pyi"), {"QueryResult": answer})
    check(hgs.clip, os.path.join(STUBS, "clip.pyi"))
    check(hgs.sam, os.path.join(STUBS, "sam.pyi"))
    missing = [n for n in hgs.__all__ if n not in names and n not in ("clip", "sam")]
    assert not missing, f"public names without a stub: {missing}"
