# Set-up and entry points. `make demo` and `make test` install everything on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
# CPU build served locally on the project machines; only installed when the venv has no torch yet.
TORCH_SPEC ?= torch==2.13.0
STAMP := $(VENV)/.volsmpl-installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: install demo test mutants report clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -c "import torch" 2>/dev/null || $(PY) -m pip install -q "$(TORCH_SPEC)"
	$(PY) -m pip install -q -e ".[test]"
	@# open3d's wheel links libusb-1.0, which minimal Debian images lack
	@$(PY) -c "import open3d" 2>/dev/null || { echo "installing libusb-1.0-0 for open3d"; \
	  $(SUDO) apt-get install -y -qq libusb-1.0-0 >/dev/null 2>&1 || \
	  { $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq libusb-1.0-0; }; }
	$(PY) -c "import open3d" || { echo "open3d does not import: install libusb-1.0-0 (apt-get install libusb-1.0-0)"; exit 1; }
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/volsmpl demo --out out

test: $(STAMP)
	$(PY) -m pytest -q -ra --durations=8

# named deliberate bugs (tools/mutants.py), each applied to a copy of the package: every one must fail a test
mutants: $(STAMP)
	$(PY) tools/mutants.py

report: $(STAMP)
	$(VENV)/bin/volsmpl report

clean:
	rm -rf out .pytest_cache
