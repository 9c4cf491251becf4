# Set-up and entry points. `make demo` and `make test` install everything on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
# CPU build served locally on the project machines; only installed when the venv has no torch yet.
TORCH_SPEC ?= torch==2.13.0
STAMP := $(VENV)/.volsmpl-installed

.PHONY: install demo test clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -c "import torch" 2>/dev/null || $(PY) -m pip install -q "$(TORCH_SPEC)"
	$(PY) -m pip install -q -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/volsmpl demo --out out

test: $(STAMP)
	$(PY) -m pytest -q -ra --durations=8

clean:
	rm -rf out .pytest_cache
