# ThermoTilt offline build: Debian's gcc-avr, Arduino core and simavr instead
# of the PlatformIO registry. `make test` works on a fresh Debian machine: it
# installs what is missing, builds everything and runs every test.

BUILD ?= build
VENV ?= .venv
PYTHON ?= python3
JOBS ?= $(shell nproc)
APT_PACKAGES := python3 python3-venv cmake make gcc g++ gcc-avr avr-libc binutils-avr arduino-core-avr simavr libsimavr-dev clang-format chromium chromium-driver postgresql
# clang 14 and its libFuzzer and sanitizer runtimes, for the fuzz targets.
FUZZ_APT_PACKAGES := clang libclang-rt-14-dev
AVR_MCUS := atmega328p atmega2560

NATIVE := $(BUILD)/native
FUZZ := $(BUILD)/fuzz
FUZZ_SECONDS ?= 600
VENV_READY := $(VENV)/.installed

SCENARIO ?= fig8
RUNS ?= runs

.PHONY: all firmware simulate demo test test-long deps system-deps python-deps build native avr bench bench-discovery chamber-floor bench-field fuzz fuzz-build lint lint-cpp lint-python clean

all: demo

deps: system-deps python-deps

# Installs only the Debian packages that are missing; needs root or sudo then.
system-deps:
	@missing=""; for package in $(APT_PACKAGES) $(FUZZ_APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$package 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$package"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then sudo=""; \
	  elif command -v sudo >/dev/null; then sudo=sudo; \
	  else echo "error: missing Debian packages:$$missing (run as root or install them)" >&2; exit 1; fi; \
	  echo "Installing Debian packages:$$missing"; \
	  $$sudo apt-get update -q && $$sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing; \
	fi

python-deps: $(VENV_READY)

$(VENV_READY): host/requirements.txt host/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -r host/requirements.txt -e host
	touch $@

native: system-deps
	cmake -S . -B $(NATIVE) -DCMAKE_BUILD_TYPE=Release
	cmake --build $(NATIVE) -j $(JOBS)

avr: native
	@for mcu in $(AVR_MCUS); do \
	  cmake -S . -B $(BUILD)/$$mcu -DCMAKE_TOOLCHAIN_FILE=cmake/avr-gcc.cmake -DAVR_MCU=$$mcu \
	    -DAVR_RUN=$(abspath $(NATIVE))/avr_run && \
	  cmake --build $(BUILD)/$$mcu -j $(JOBS) || exit 1; \
	done

build: native avr

# Both firmware images and their sizes.
firmware: avr
	@echo; for image in atmega328p/imu_reader atmega2560/thermal_chamber; do \
	  mcu=$${image%%/*}; \
	  echo "== $(BUILD)/$$image.hex"; \
	  avr-size --format=avr --mcu=$$mcu $(BUILD)/$$image.elf | grep -E "Program|Data"; \
	done

# The main job: a paper experiment in the digital twin (both firmware images in
# simavr against the physics model); SCENARIO=cycle, campaign, field-warming...
simulate: build python-deps
	$(VENV)/bin/thermotilt simulate $(SCENARIO) --out $(RUNS)/$(SCENARIO) --force

# The main job: the paper's calibration end to end in the twin - campaign,
# fit, compare, upload through the IMU's serial port, field validation.
# Writes docs/paper-comparison.md.
demo: build python-deps
	DEMO_DIR=$(RUNS)/demo THERMOTILT_BUILD_DIR=$(abspath $(BUILD)) $(VENV)/bin/python host/tools/demo.py

# How fast the twin runs, the firmware's CPU and RAM use, the fits' times and
# the line check; prints the figures and writes docs/performance.md.
bench: build python-deps
	THERMOTILT_BUILD_DIR=$(abspath $(BUILD)) $(VENV)/bin/python host/tools/bench.py

# Discovery's error rates over hundreds of runs on a Dask cluster (a
# LocalCluster of this machine's cores, or SCHEDULER=tcp://HOST:8786): runs
# what docs/benchmarks/discovery-runs.csv lacks, then writes the rates into
# docs/discovery.md and docs/benchmarks/discovery-rates.png.
bench-discovery: build python-deps
	THERMOTILT_BUILD_DIR=$(abspath $(BUILD)) $(VENV)/bin/python host/tools/bench_discovery.py $(if $(SCHEDULER),--scheduler $(SCHEDULER))

# What the chamber's replay leaves on the twin's own runs from the default
# model: the floor discovery declares on the chamber's channels, written to
# host/thermotilt/discovery/chamber_floor.toml (twin runs kept in
# build/chamber-floor).
chamber-floor: build python-deps
	THERMOTILT_BUILD_DIR=$(abspath $(BUILD)) $(VENV)/bin/python host/tools/chamber_floor.py

# Whether each sensor's certificate bounds what a monitoring user reads in the
# field: sensors drawn from the batch population, calibrated through one twin
# campaign (kept in build/bench-field) and replayed through the field profiles
# on a Dask cluster (a LocalCluster of this machine's cores, or
# SCHEDULER=tcp://HOST:8786); runs what docs/benchmarks/field-runs.csv lacks,
# then writes docs/benchmarks/field-accuracy.md and its figure.
bench-field: build python-deps
	THERMOTILT_BUILD_DIR=$(abspath $(BUILD)) $(VENV)/bin/python host/tools/bench_field.py $(if $(SCHEDULER),--scheduler $(SCHEDULER))

fuzz-build: system-deps
	cmake -S fuzz -B $(FUZZ) -DCMAKE_CXX_COMPILER=clang++
	cmake --build $(FUZZ) -j $(JOBS)

# Every libFuzzer target for FUZZ_SECONDS (make test gives each 20 s).
fuzz: fuzz-build
	@bash fuzz/run.sh $(FUZZ) $(FUZZ_SECONDS)

# The project's C/C++ sources against .clang-format (cmake/ holds the vendored
# Unity fallback, which keeps its own layout); exits non-zero on a violation.
CPP_SOURCES := $(foreach dir,lib firmware sim test fuzz host/native,'$(dir)/*.c' '$(dir)/*.cpp' '$(dir)/*.h')
lint-cpp: system-deps
	@command -v clang-format >/dev/null || { echo "error: clang-format is missing: make system-deps" >&2; exit 1; }
	git ls-files -z -- $(CPP_SOURCES) | xargs -0 clang-format --dry-run --Werror

# The host package and its tests against ruff's rules and layout; the
# package's imports against its layers (import-linter) and the size of its
# functions and modules (flake8-max-function-length, pylint's
# too-many-lines), as host/pyproject.toml and host/.flake8 set them.
lint-python: python-deps
	$(VENV)/bin/ruff check host
	$(VENV)/bin/ruff format --check host
	cd host && $(abspath $(VENV))/bin/lint-imports --no-logo --no-cache
	cd host && $(abspath $(VENV))/bin/flake8 thermotilt
	cd host && $(abspath $(VENV))/bin/pylint --score=no thermotilt

lint: lint-cpp lint-python

test: build fuzz-build python-deps lint
	@BUILD=$(BUILD) VENV=$(VENV) bash cmake/run-tests.sh $(AVR_MCUS)

# The tests make test leaves out: make demo's whole twin campaign and every
# discovery candidate in a twin run (about 15 min of CPU).
test-long: build python-deps
	$(VENV)/bin/python -m pytest host/tests -m long -n $${PYTEST_WORKERS:-auto} --dist worksteal

clean:
	rm -rf $(BUILD)
