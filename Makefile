# The two commands of the README. Both run scripts/setup first (installs Debian packages if missing).
BUILD ?= build
JOBS ?= $(shell nproc)

.PHONY: all setup build test demo package clean sanitize

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

# The Debian package $(BUILD)/bodyd_<version>_<arch>.deb (CPack; docs/install.md):
# sudo apt install ./$(BUILD)/bodyd_*.deb
package: build
	@cd $(BUILD) && cpack -G DEB

# ASan/UBSan build and test run (slower; in build-asan/).
sanitize: setup
	@cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=Debug -DBODYD_SANITIZE=ON >/dev/null
	@cmake --build build-asan -j $(JOBS)
	@cd build-asan && LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp ctest --output-on-failure -j $(JOBS)

clean:
	rm -rf $(BUILD) build-asan
