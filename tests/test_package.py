"""The package's top level: the version, every listed submodule, the public names."""

import importlib
import importlib.metadata
from pathlib import Path

import rffqm_nlp as rq


def test_version_comes_from_the_installed_metadata():
    assert rq.__version__ == importlib.metadata.version("rffqm_nlp")


def test_every_module_of_the_package_imports_and_every_listed_name_resolves():
    root = Path(rq.__file__).parent
    for path in root.rglob("*.py"):
        parts = path.relative_to(root).with_suffix("").parts
        name = ".".join(("rffqm_nlp",) + parts[:-1] if parts[-1] == "__init__"
                        else ("rffqm_nlp",) + parts)
        assert importlib.import_module(name).__name__ == name
    for name, where in rq.MODULES.items():
        assert getattr(rq, name).__name__ == f"rffqm_nlp.{where}"


def test_public_names_resolve():
    for name in rq.__all__:
        assert getattr(rq, name) is not None
    assert callable(rq.collisions) and rq.collisions.__module__ == "rffqm_nlp.contact.collisions"
