# Albedit: `make run` starts the app, `make test` runs the whole suite, `make lint` ruff and mypy.
# Both build .venv from scratch on first use.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: run test bench demo clean lint

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,gphoto2,harvesters,mitsuba]"
	# without its dependencies: it pins opencv-python, whose cv2 would replace the contrib build's
	$(PY) -m pip install --quiet --no-deps "colour-checker-detection>=0.2.3"
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/albedit

demo: $(STAMP)
	$(VENV)/bin/albedit demo

test: $(STAMP)
	QT_QPA_PLATFORM=offscreen $(VENV)/bin/lint-imports
	QT_QPA_PLATFORM=offscreen $(PY) -m pytest engine devices app tests

# ruff (pyflakes, pycodestyle, isort, pyupgrade, bugbear) on the tree, mypy on engine/ and devices/;
# both configured in pyproject.toml (.pre-commit-config.yaml runs the same two)
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

bench: $(STAMP)
	$(PY) bench/solve.py
	$(PY) bench/recolor.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
