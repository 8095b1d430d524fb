# Every target installs what it needs on first use: a .venv from PyPI only (no root, no apt).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install hil-sim test bench soak fuzz credibility synth lint clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,bench]'
	touch $(STAMP)

# The demo flight, watched live in a browser: it prints the view's URL (127.0.0.1:8765).
hil-sim: $(STAMP)
	$(BIN)/rig hil-sim --view $(if $(PX4_DIR),--autopilot px4 --px4 $(PX4_DIR))

# The test files are shared out between TEST_WORKERS processes (pytest-xdist; a file's
# tests stay together, so its module fixtures run once); TEST_WORKERS=0 runs them in one.
TEST_WORKERS ?= 2
test: $(STAMP)
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile

bench: $(STAMP)
	$(BIN)/python -m benchmarks

# A day of simulated flight in one run: memory per simulated hour, logs read back whole
# (about 3 hours here; SOAK_HOURS=1 for a quick look).
SOAK_HOURS ?= 24
soak: $(STAMP)
	$(BIN)/python -m benchmarks.soak --hours $(SOAK_HOURS)

# Every input path (logs, TOML, MAVLink ports) fuzzed coverage-guided for FUZZ_MINUTES.
FUZZ_MINUTES ?= 10
fuzz: $(STAMP)
	$(BIN)/python -m benchmarks.fuzz --minutes $(FUZZ_MINUTES)

# The paper's section-4 study on the real X500 flight (README "How credible is this rig?"):
# the flight replayed by the high- (x500_v2) and low-precision (x500_v2_low_precision) models,
# the 1-DOF pitch bench sweep, then the two reports. With PX4_DIR set (CI: ../shared/px4_sitl)
# PX4 SITL, the firmware that flew it, replays the whole flight with the log's own parameters
# as its pilot flew it (one replay per model serves every test); without it the reference
# autopilot replays it through each of its loops.
# Finished runs are kept (make reruns only what is missing; `make clean` starts over); a run
# counts as finished by its .complete stamp, so an interrupted run's readable logs are kept
# until it is flown again (--force).
# A report whose verdict is "fail" (exit 1) is a result, not a build error; bad input (2) and a
# report that could not be scored (3: a topic missing, a replay too short) are.
X500_LOG    := data/flight_logs/px4_x500v2_v6xrt_flight_2026-03-20.ulg
STUDY       := runs/credibility/x500
REPORTS     := runs/credibility/reports
MODEL_high  := x500_v2
MODEL_low   := x500_v2_low_precision
DRIVE_velocity :=
DRIVE_attitude := --drive attitude --window 470 480 --end 482
DRIVE_rates    := --drive rates --window 455 481.5 --end 482
ifdef PX4_DIR
STUDY_WHAT  := PX4 SITL ($(PX4_DIR)) with the log's own parameters
REPLAYS     := px4
STUDY_LOGS  := $(foreach role,sim sim_attitude sim_rates,--log $(role)=$(STUDY)/px4_high/px4.ulg) \
               $(foreach role,sim_low sim_attitude_low sim_rates_low,\
                 --log $(role)=$(STUDY)/px4_low/px4.ulg)
VALIDATION  := x500_validation_px4
else
STUDY_WHAT  := the reference autopilot (set PX4_DIR to fly PX4)
REPLAYS     := velocity attitude rates
STUDY_LOGS  :=
VALIDATION  := x500_validation
endif
STUDY_RUNS  := $(foreach run,$(REPLAYS) bench,\
                 $(foreach model,high low,$(STUDY)/$(run)_$(model)/.complete))

credibility: $(STUDY_RUNS)
	@echo "credibility study: the X500 flight flown by $(STUDY_WHAT); models $(MODEL_high)" \
		"(high precision) and $(MODEL_low) (low)"
	$(BIN)/credibility report credibility/plans/x500_pitch_bench.toml \
		--out $(REPORTS)/x500_pitch_bench || [ $$? -eq 1 ]
	$(BIN)/credibility report credibility/plans/x500_validation.toml $(STUDY_LOGS) \
		--out $(REPORTS)/$(VALIDATION) || [ $$? -eq 1 ]

$(STUDY)/bench_%/.complete: | $(STAMP)
	$(BIN)/rig run pitch_sweep_bench --vehicle $(MODEL_$*) --out $(@D) --force
	touch $@

$(STUDY)/px4_%/.complete: $(X500_LOG) | $(STAMP)
	$(BIN)/rig replay $(X500_LOG) --autopilot px4 --px4 $(PX4_DIR) --vehicle $(MODEL_$*) \
		--out $(@D) --force
	touch $@

$(STUDY)/%/.complete: $(X500_LOG) | $(STAMP)
	$(BIN)/rig replay $(X500_LOG) $(DRIVE_$(firstword $(subst _, ,$*))) \
		--vehicle $(MODEL_$(lastword $(subst _, ,$*))) --out $(@D) --force
	touch $@

# SensorTop synthesized, placed and routed for a Lattice ECP5-85F with YoWASP's Yosys and
# nextpnr from PyPI, plus a Kintex-7 estimate: fails if it does not fit or misses a clock
# (about 70 s here; figures and logs in build/synth/).
synth: $(STAMP)
	$(BIN)/python -m fpga_hdl.synth

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports

clean:
	rm -rf build runs .pytest_cache
