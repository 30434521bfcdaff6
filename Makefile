# Filigree: `make demo` runs the main job end to end, `make test` runs every test.
# Both install missing Debian packages, configure and build first.

BUILD ?= build
JOBS  ?= $(shell nproc)

.PHONY: all deps configure build test demo bench clean viewer serve

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

test: build viewer
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

demo: build viewer
	bash scripts/demo.sh $(BUILD)

# A server with the demo session, for a person with a browser (Ctrl-C stops it).
serve: build viewer
	bash scripts/serve.sh $(BUILD)

bench: build
	$(BUILD)/bench/filigree_bench_preprocess
	$(BUILD)/bench/filigree_bench_runtime
	$(BUILD)/bench/filigree_bench_service

clean:
	rm -rf $(BUILD) out
