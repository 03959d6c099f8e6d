# Thin wrapper over CMake presets, ctest and the dependency install. Every target installs what is missing first.
SHELL := /bin/bash
.DEFAULT_GOAL := build
JOBS ?= $(shell nproc)
export CMAKE_BUILD_PARALLEL_LEVEL := $(JOBS)
export CTEST_PARALLEL_LEVEL := $(JOBS)

.PHONY: deps build cross tsan asan test test-native test-cross test-tsan test-asan test-slurm bench package demo clean help fuzz

help:
	@echo "make deps     install missing Debian packages (apt-get; root or sudo) and the arm64 sysroot"
	@echo "make build    build the native (x86-64-v3) tree: role binaries, tests, benchmarks"
	@echo "make test     native tests, the aarch64 cross build with its unit tests under qemu, the ring stress under TSan"
	@echo "make bench    ring throughput/latency vs moodycamel, scheduler wake-up lateness"
	@echo "make package  .deb per role (stripped) and its -dbgsym for amd64 and arm64 in build/*/packages, checked by lintian"
	@echo "make demo     the default simulated mission (1 quadrotor, 3 ground robots, region investigation) and its report in build/demo"
	@echo "make fuzz     build the libFuzzer targets with clang and run each FUZZ_SECONDS (default 60)"
	@echo "make test-slurm  a 4-mission study through a single-node Slurm started for the test, against the same grid run locally (~4 min; not in make test)"

deps:
	@tools/install-deps.sh

build: deps
	cmake --preset native
	cmake --build --preset native

cross: deps
	cmake --preset xavier-nx
	cmake --build --preset xavier-nx

tsan: deps
	cmake --preset tsan
	cmake --build --preset tsan --target airground_stress_tests

asan: deps
	cmake --preset asan
	cmake --build --preset asan

test-native: build
	ctest --preset native

test-cross: cross
	ctest --preset xavier-nx

test-tsan: tsan
	ctest --preset tsan

test-asan: asan
	ctest --preset asan

test: test-native test-cross test-tsan
	@echo "make test: native, aarch64 (qemu) and ThreadSanitizer suites passed"

# Not part of `make test` (minutes, and it starts its own munged, slurmctld and slurmd as root):
# Debian's Slurm and MUNGE come from tools/install-slurm.sh, not from `make deps`.
test-slurm: build
	@tools/install-slurm.sh
	tests/slurm/test_slurm_study.sh build/native/sim/airground-sim

bench: build
	cmake --build --preset native --target bench

# Each role's package (stripped binary) and its -dbgsym package, then lintian on every one: an error fails.
package: build cross
	rm -f build/native/packages/*.deb build/xavier-nx/packages/*.deb
	cd build/native && cpack -G DEB
	cd build/xavier-nx && cpack -G DEB
	lintian --fail-on error --tag-display-limit 0 build/native/packages/*.deb build/xavier-nx/packages/*.deb
	@ls -l build/native/packages/*.deb build/xavier-nx/packages/*.deb

DEMO_OUT ?= build/demo
DEMO_ARGS ?=
demo: build
	build/native/sim/airground-sim mission --world default --ugvs 3 --seed 1 --verbose 120 --out $(DEMO_OUT) $(DEMO_ARGS)
	@echo "make demo: report in $(DEMO_OUT)/report.md (metrics.json, mission_map.png, pose_error.png, claims_timeline.png, maps/)"

# libFuzzer targets (Debian's clang): build them apart from the main tree and run each FUZZ_SECONDS.
FUZZ_SECONDS ?= 60
fuzz: deps
	cmake -S tests/fuzz -B build/fuzz -G Ninja -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo
	cmake --build build/fuzz
	mkdir -p build/fuzz/corpus/comms_datagram
	build/fuzz/fuzz_comms_datagram -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 build/fuzz/corpus/comms_datagram tests/fuzz/comms/seeds
	for t in ouster_packet ublox_stream candump_line cannelloni; do \
	  mkdir -p build/fuzz/corpus/$$t && \
	  build/fuzz/fuzz_$$t -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 build/fuzz/corpus/$$t tests/fuzz/drivers/seeds/$$t || exit 1; \
	done

clean:
	rm -rf build
