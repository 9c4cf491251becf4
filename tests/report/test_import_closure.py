"""volsmpl.report.import_closure: the repository files a producer's code reaches through imports, read from the source."""
from __future__ import annotations

from pathlib import Path

from volsmpl.report.import_closure import module_file, producer_closure

FILES = {
    "core/__init__.py": "from .volume import Volume\n",
    "core/volume.py": "import torch\nfrom . import boxes\n\ndef f():\n    from .lazy import g  # a lazy import\n",
    "core/boxes.py": "",
    "core/lazy.py": "from volsmpl.nn.net import Net\n",
    "core/nn/__init__.py": "",
    "core/nn/net.py": "",
    "core/models.py": 'REGISTRY = {"coap": "volsmpl.nn.coap:CoapNet"}\n',
    "core/nn/coap.py": "",
    "core/unrelated.py": "",
    "core/report.py": "import volsmpl.unrelated\n",
    "apps/__init__.py": "",
    "apps/demo/__init__.py": "",
    "apps/demo/run.py": "from volsmpl.models import REGISTRY\nfrom .steps import step\nfrom ..other import x\n",
    "apps/demo/steps.py": "import numpy as np\n",
    "apps/demo/cases.json": "[]\n",
    "apps/other.py": "",
}


def make_tree(root: Path) -> Path:
    for rel, text in FILES.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


def test_closure_follows_imports_lazy_relative_registry_and_parent_packages(tmp_path):
    root = make_tree(tmp_path)
    got = set(producer_closure(("apps/demo", "data/table.csv"), root))
    expected = {"apps/demo", "data/table.csv",  # entries as given (a folder covers its data files)
                "apps/__init__.py", "apps/demo/__init__.py", "apps/demo/run.py", "apps/demo/steps.py",
                "apps/other.py",                                   # from ..other import x
                "core/models.py", "core/nn/coap.py",               # the registry's string names coap
                "core/__init__.py", "core/volume.py", "core/boxes.py",  # volsmpl/__init__ runs first
                "core/lazy.py", "core/nn/__init__.py", "core/nn/net.py"}  # a lazy import inside a function
    assert got == expected
    assert "core/unrelated.py" not in got and "core/report.py" not in got


def test_module_file_maps_the_package_dirs(tmp_path):
    root = make_tree(tmp_path)
    assert module_file("volsmpl", root) == root / "core/__init__.py"
    assert module_file("volsmpl.nn", root) == root / "core/nn/__init__.py"
    assert module_file("volsmpl.apps.demo.run", root) == root / "apps/demo/run.py"
    assert module_file("volsmpl.nn.missing", root) is None and module_file("numpy", root) is None
