# The two commands of the README. Both run scripts/setup first (installs Debian packages if missing).
BUILD ?= build
JOBS ?= $(shell nproc)

.PHONY: all setup build test demo package clean sanitize fuzz

all: build

setup:
	@scripts/setup

build: setup
	@cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
	@cmake --build $(BUILD) -j $(JOBS)

test: build
	@cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

demo: build
	@scripts/demo $(BUILD)

# The Debian package $(PACKAGE_BUILD)/bodyd_<version>_<arch>.deb (CPack; docs/install.md):
# sudo apt install ./$(PACKAGE_BUILD)/bodyd_*.deb. Its own build tree builds only what ships
# (BODYD_BUILD_TESTS=OFF: no tests, no test tools), and setup installs only the build
# dependencies (BODYD_SETUP_PACKAGE=1: no browser, no npm).
PACKAGE_BUILD ?= build-package
package:
	@BODYD_SETUP_PACKAGE=1 scripts/setup
	@cmake -S . -B $(PACKAGE_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBODYD_BUILD_TESTS=OFF >/dev/null
	@cmake --build $(PACKAGE_BUILD) -j $(JOBS)
	@cd $(PACKAGE_BUILD) && cpack -G DEB

# ASan/UBSan build and test run (slower; in build-asan/).
sanitize: setup
	@cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=Debug -DBODYD_SANITIZE=ON >/dev/null
	@cmake --build build-asan -j $(JOBS)
	@cd build-asan && LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp ctest --output-on-failure -j $(JOBS)

# libFuzzer run of every fuzz target, FUZZ_SECONDS each, one after another (clang; in
# build-fuzz/; docs/reliability.md). FUZZ_TARGETS="bvh config" picks some.
FUZZ_BUILD ?= build-fuzz
FUZZ_SECONDS ?= 60
FUZZ_TARGETS ?=
fuzz:
	@BODYD_SETUP_FUZZ=1 scripts/setup
	@scripts/fuzz --build $(FUZZ_BUILD) --seconds $(FUZZ_SECONDS) --jobs $(JOBS) $(FUZZ_TARGETS)

clean:
	rm -rf $(BUILD) build-asan $(FUZZ_BUILD) $(PACKAGE_BUILD)
