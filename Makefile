# cubesim — hand-written Makefile with dependency files (in the manner of Redis' src/Makefile).
#
#   make deps     install every Debian package the project needs (idempotent)
#   make          build everything into build/bin/
#   make test     unit tests (sanitizer build) + integration tests; ends "N passed, N failed"
#   make run      the demonstration on the default scene
#   make bench    benchmarks; figures to bench/results/
#   make stress   longer stability suites
#   make valgrind unit tests under valgrind
#   make fuzz     coverage-guided fuzzing of the scene parser and the clients' surface state
#                 (clang's libFuzzer; FUZZ_SECONDS each, default 120)
#   make san      the address/undefined-sanitizer build into build/san/

PACKAGES := build-essential pkg-config liblcm-dev liblcm-bin libglib2.0-dev libassimp-dev assimp-testmodels \
            libcjson-dev libccd-dev iproute2 util-linux valgrind gnuplot-nox

CC      ?= cc
SAN     ?= 0
ifeq ($(SAN),1)
B       := build/san
OPT     := -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=all
else
B       := build
OPT     := -O3 -g -march=x86-64-v2
endif

PKGS    := lcm assimp libcjson ccd
PKG_CFLAGS := $(shell pkg-config --cflags $(PKGS) 2>/dev/null)
PKG_LIBS   := $(shell pkg-config --libs $(PKGS) 2>/dev/null)

GEN     := build/gen
WARN    := -Wall -Wextra -Werror -Wshadow -Wno-unused-parameter
CFLAGS_ALL := -std=c11 -D_GNU_SOURCE $(OPT) -fopenmp -MMD -MP $(PKG_CFLAGS) -I. -Iserver/engine -Icommon -I$(GEN)
CFLAGS_OWN := $(CFLAGS_ALL) $(WARN)
LDLIBS  := -fopenmp $(PKG_LIBS) -lm -lpthread

LCM_SRC    := $(wildcard lcmtypes/*.lcm)
GEN_C      := $(patsubst lcmtypes/%.lcm,$(GEN)/cubesim_%.c,$(LCM_SRC))
GEN_H      := $(GEN_C:.c=.h)
ENGINE_SRC := $(wildcard server/engine/*.c)
COMMON_SRC := $(wildcard common/*.c)
SERVER_SRC := $(wildcard server/*.c)
CLIENT_SRC := $(wildcard client/cubesim-*.c)
CLIENT_LIB_SRC := $(filter-out client/cubesim-%.c,$(wildcard client/*.c))
UNIT_SRC   := $(wildcard tests/unit/*.c)
BENCH_SRC  := $(wildcard bench/*.c)
IT_TOOL_SRC := $(wildcard tests/it/tools/*.c)
STRESS_TOOL_SRC := $(wildcard tests/stress/*.c)

obj = $(patsubst %.c,$(B)/obj/%.o,$(1))

LIB_ENGINE := $(B)/lib/libcsengine.a
LIB_COMMON := $(B)/lib/libcscommon.a
LIB_TYPES  := $(B)/lib/libcstypes.a
LIB_CLIENT := $(B)/lib/libcsclient.a
LIBS       := $(LIB_CLIENT) $(LIB_ENGINE) $(LIB_COMMON) $(LIB_TYPES)

BINS := $(B)/bin/cubesimd $(patsubst client/%.c,$(B)/bin/%,$(CLIENT_SRC)) \
        $(B)/bin/cs_unit_tests $(patsubst bench/%.c,$(B)/bin/%,$(BENCH_SRC)) \
        $(patsubst tests/it/tools/%.c,$(B)/bin/cs_it_%,$(IT_TOOL_SRC)) \
        $(patsubst tests/stress/%.c,$(B)/bin/cs_stress_%,$(STRESS_TOOL_SRC))

.PHONY: all deps test run bench stress valgrind san clean gen fuzz
all: $(BINS)

deps:
	@missing=""; for p in $(PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing:$$missing"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing; \
	else echo "all packages present"; fi

gen: $(GEN_C)

# The generated sources are kept: otherwise make deletes them as intermediates after a fresh
# build, and a client cannot compile against build/gen until a second make.
.SECONDARY: $(GEN_C) $(GEN_H)

$(GEN)/cubesim_%.c $(GEN)/cubesim_%.h: lcmtypes/%.lcm
	@mkdir -p $(GEN)
	lcm-gen -c --c-cpath $(GEN) --c-hpath $(GEN) $<

# Generated code is not ours: compiled without -Werror.
$(B)/obj/$(GEN)/%.o: $(GEN)/%.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -w -c $< -o $@

$(B)/obj/%.o: %.c | $(GEN_H)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_OWN) -c $< -o $@

$(LIB_TYPES): $(call obj,$(GEN_C))
$(LIB_ENGINE): $(call obj,$(ENGINE_SRC))
$(LIB_COMMON): $(call obj,$(COMMON_SRC))
$(LIB_CLIENT): $(call obj,$(CLIENT_LIB_SRC))
$(B)/lib/%.a:
	@mkdir -p $(dir $@)
	rm -f $@ && ar rcs $@ $^

$(B)/bin/cubesimd: $(call obj,$(SERVER_SRC)) $(LIBS)
	@mkdir -p $(dir $@)
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

$(B)/bin/cubesim-%: $(B)/obj/client/cubesim-%.o $(LIBS)
	@mkdir -p $(dir $@)
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

# The unit tests also drive the daemon's bus adapter (server/bus.c) through LCM's file provider.
$(B)/bin/cs_unit_tests: $(call obj,$(UNIT_SRC)) $(call obj,server/bus.c server/dlog.c) $(LIBS)
	@mkdir -p $(dir $@)
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

$(B)/bin/bench_%: $(B)/obj/bench/bench_%.o $(LIBS)
	@mkdir -p $(dir $@)
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

# Integration-test tools (tests/it/tools/NAME.c -> cs_it_NAME): small LCM senders/receivers.
$(B)/bin/cs_it_%: $(B)/obj/tests/it/tools/%.o $(LIBS)
	@mkdir -p $(dir $@)
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

san:
	$(MAKE) SAN=1 all

test: deps
	$(MAKE) all
	$(MAKE) SAN=1 all
	bash tests/run_all.sh

valgrind: all
	valgrind --error-exitcode=1 --leak-check=full --errors-for-leak-kinds=definite --show-possibly-lost=no \
	  --suppressions=tests/stress/lcm.supp $(B)/bin/cs_unit_tests --quick

# libFuzzer targets (tests/fuzz): the fuzzed code (common/) is compiled by clang with coverage,
# address and undefined-behaviour instrumentation; the engine, which needs GCC (target_clones,
# vector extensions), is linked from the release build uninstrumented. Corpora and any crash
# reproducer go to build/fuzz/. Not part of `make test`: clang is not one of the packages.
FUZZ_SECONDS ?= 120
FUZZ_FLAGS := -O1 -g -std=c11 -D_GNU_SOURCE -fsanitize=fuzzer,address,undefined \
              -I. -Iserver/engine -Icommon -I$(GEN) $(shell pkg-config --cflags glib-2.0 libcjson)
FUZZ_LIBS := $(PKG_LIBS) -lgomp -lm -lpthread
fuzz:
	$(MAKE) SAN=0 all
	@command -v clang >/dev/null || { echo "make fuzz needs clang (apt-get install clang)"; exit 1; }
	@mkdir -p build/fuzz/scene build/fuzz/surface_state
	clang $(FUZZ_FLAGS) tests/fuzz/fuzz_scene.c $(COMMON_SRC) -o build/fuzz/fuzz_scene \
	  build/lib/libcsengine.a build/lib/libcstypes.a $(FUZZ_LIBS)
	clang $(FUZZ_FLAGS) tests/fuzz/fuzz_surface_state.c $(COMMON_SRC) -o build/fuzz/fuzz_surface_state \
	  build/lib/libcsengine.a build/lib/libcstypes.a $(FUZZ_LIBS)
	cp scenes/*.json build/fuzz/scene/
	build/fuzz/fuzz_scene -max_total_time=$(FUZZ_SECONDS) -timeout=20 -max_len=4096 \
	  -artifact_prefix=build/fuzz/ build/fuzz/scene
	build/fuzz/fuzz_surface_state -max_total_time=$(FUZZ_SECONDS) -timeout=10 -max_len=2048 \
	  -artifact_prefix=build/fuzz/ build/fuzz/surface_state

run: deps all
	bash scenes/demo.sh

bench: all
	bash bench/run.sh

# Stress-suite tools (tests/stress/NAME.c -> cs_stress_NAME), used by tests/stress.sh.
$(B)/bin/cs_stress_%: $(B)/obj/tests/stress/%.o $(LIBS)
	@mkdir -p $(dir $@)
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

stress: all
	bash tests/stress.sh

clean:
	rm -rf build

-include $(shell find build -name '*.d' 2>/dev/null)
