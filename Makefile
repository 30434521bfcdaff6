# Filigree: `make demo` runs the main job end to end, `make test` runs every test.
# Both install missing Debian packages, configure and build first.

BUILD ?= build
JOBS  ?= $(shell nproc)

.PHONY: all deps configure build test test-cluster demo bench clean viewer serve image test-container install fuzz-build fuzz

all: build viewer

deps:
	bash scripts/install-deps.sh

$(BUILD)/build.ninja:
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release

configure: deps $(BUILD)/build.ninja

build: configure
	cmake --build $(BUILD) -j $(JOBS)

# The web viewer (web_viewer/dist, what filigree-server --http serves by default).
viewer: deps
	bash web_viewer/build.sh

test: build viewer fuzz-build
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

# The libFuzzer targets (tests/fuzz) with clang, ASan and UBSan, in their own
# build; `make test` replays their corpora (ctest fuzz_corpus_replay).
FUZZ_BUILD ?= build-fuzz
$(FUZZ_BUILD)/build.ninja:
	cmake -S . -B $(FUZZ_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ -DFILIGREE_FUZZ=ON

fuzz-build: deps $(FUZZ_BUILD)/build.ninja
	cmake --build $(FUZZ_BUILD) -j $(JOBS) --target fuzz_all

# Each target for FUZZ_SECONDS (default 600), two at a time; findings in out/fuzz/crashes.
fuzz: fuzz-build
	bash tests/fuzz/run.sh fuzz $(FUZZ_BUILD)

# Only the replicas test (Redis, three replicas, nginx on loopback); `make test` runs it too.
test-cluster: build
	ctest --test-dir $(BUILD) --output-on-failure -R '^Cluster\.'

# The container image (podman; base image from a debootstrap rootfs) and a
# smoke test of a container from it: health check and a demo session on loopback.
image:
	bash scripts/install-deps.sh --container
	bash docker/build-image.sh

test-container: image
	bash docker/smoke-test.sh

demo: build viewer
	bash scripts/demo.sh $(BUILD)

# A server with the demo session, for a person with a browser (Ctrl-C stops it).
serve: build viewer
	bash scripts/serve.sh $(BUILD)

# The client library, libfiligree.so, the CLI and server, and the Python
# package into /usr/local (PREFIX=...), then the loader's cache.
PREFIX ?= /usr/local
install: build
	cmake --install $(BUILD) --prefix $(PREFIX)
	ldconfig

bench: build
	$(BUILD)/bench/filigree_bench_preprocess
	$(BUILD)/bench/filigree_bench_runtime
	$(BUILD)/bench/filigree_bench_service
	$(BUILD)/bench/filigree_bench_history
	$(BUILD)/bench/filigree_bench_encoder
	$(BUILD)/bench/filigree_bench_cluster
	$(BUILD)/bench/filigree_bench_upstream

# 16 sessions driven at 30 Hz with watchers and malformed requests for
# SOAK_SECONDS (default 600) against the just-built server; fails on a lost
# pose, a version going backwards, an unexpected status or memory growth.
# Not part of `make test` (which runs a 20 s smoke of it).
SOAK_SECONDS ?= 600
.PHONY: soak
soak: build
	$(BUILD)/bench/filigree_soak --seconds $(SOAK_SECONDS) --server $(BUILD)/server/filigree-server

clean:
	rm -rf $(BUILD) $(FUZZ_BUILD) out
