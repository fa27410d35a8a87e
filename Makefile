# Albedit: `make run` starts the app, `make test` runs the whole suite.
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

bench: $(STAMP)
	$(PY) bench/solve.py
	$(PY) bench/recolor.py

clean:
	rm -rf $(VENV) .pytest_cache
