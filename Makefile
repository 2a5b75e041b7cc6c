# MirrorCap: `make demo` runs the main job on the embedded sample, `make test` runs the tests.
# Both create the virtual environment .venv on first use (Python 3.11, pinned requirements).

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cat requirements.txt requirements-dev.txt pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: demo test bench sample head rig-clip extension contact-sheet clean venv

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else "MirrorCap needs Python 3.11 (bpy 5.0.1); set PYTHON=/path/to/python3.11")'
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps -e .
	@rm -f $(VENV)/.installed-*
	@touch $@

demo: $(STAMP)
	$(VENV)/bin/mirrorcap demo --out out

test: $(STAMP)
	$(PY) -m pytest

bench: $(STAMP)
	$(PY) -m benchmarks.run --out bench_results

sample: $(STAMP)
	$(PY) sample_scenes/make_mirror_demo.py

# Re-render the sample rig clip with Cycles (about 12 minutes on 2 cores; frames are cached).
rig-clip: $(STAMP)
	$(PY) sample_scenes/make_rig_clip.py

# The Blender extension: fetch the pinned wheels, validate, one zip per platform into dist/.
extension: $(STAMP)
	$(PY) tools/extension.py build --out dist

clean:
	rm -rf $(VENV) out build dist wheels *.egg-info .pytest_cache

head: $(STAMP)
	$(PY) sample_scenes/make_generic_head.py

contact-sheet: $(STAMP)
	$(PY) sample_scenes/make_contact_sheet.py
