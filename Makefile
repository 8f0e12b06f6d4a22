# acquisitiond — top-level build.  GNU make, C17, out-of-tree objects, programs in $(BUILD)/.
#
# Conventions (so a new file needs no Makefile edit):
#   <folder>/*_main.c        a program's entry point: build/<name with _ → ->   (see PROGRAMS)
#   <folder>/<name>/*.c      files of that program only (command handlers), linked before the libraries
#   <folder>/*.c (others)    the folder's static library build/lib<folder>.a
#   <folder>/<sub>/*.c       a sub-folder listed in LIBDIRS: its own library build/lib<sub>.a (daemon/plan/ →
#                            build/libplan.a, the planner that acqctl links without the daemon)
#   tests/unit/test_*.c      a cmocka unit test, linked with every library
#   tests/integration/test_* an executable script (sh/py), run by tests/run-integration.sh
#   tests/bench/bench_*.c    a benchmark program, run by `make bench`
#   tests/fuzz/fuzz_*.c      a libFuzzer target (LLVMFuzzerTestOneInput): `make fuzz` builds it with clang;
#                            `make check` replays its corpus tests/fuzz/corpus/<name>/ through a plain driver.
#   <folder>/module.mk       optional extra rules of a folder (generated sources, data files).

SHELL      := /bin/bash
PREFIX     ?= /usr/local
DESTDIR    ?=
SANITIZE   ?=
CC         ?= cc
ifeq ($(origin CC),default)
CC := cc
endif

ifeq ($(SANITIZE),)
BUILD      ?= build
else
BUILD      ?= build/san
endif

VERSION    := $(shell git describe --always --dirty 2>/dev/null || echo 0.1)

PKGS       := libusb-1.0 libmodbus libserialport sqlite3 yaml-0.1 lapacke openblas libsystemd libpng jansson cairo OpenEXR hdf5
PKG_CFLAGS := $(shell pkg-config --cflags $(PKGS) 2>/dev/null)
PKG_LIBS   := $(shell pkg-config --libs $(PKGS) 2>/dev/null)

WARN       := -Wall -Wextra -Werror -Wshadow -Wmissing-prototypes -Wstrict-prototypes -Wcast-qual \
              -Wsign-compare -Wpointer-arith -Wformat=2 -Wno-format-nonliteral -Wno-format-truncation -Wundef -Wvla
CFLAGS     ?= -O2 -g
ALL_CFLAGS := -std=c17 -D_GNU_SOURCE $(WARN) $(CFLAGS) -I. -I$(BUILD)/gen $(PKG_CFLAGS) -MMD -MP
V ?= 0
ifeq ($(V),0)
Q := @
endif
LDLIBS     := $(PKG_LIBS) -lm -lpthread

ifneq ($(SANITIZE),)
ALL_CFLAGS += -fsanitize=$(SANITIZE) -fno-omit-frame-pointer -fno-sanitize-recover=all
LDFLAGS    += -fsanitize=$(SANITIZE)
endif

# Folders that form libraries, in link order (users before providers); a sub-folder names its library.
LIBDIRS    := daemon daemon/plan sim proto recon drivers config
# A program that links fewer libraries than all (in link order): PROG_LIBDIRS_<program>.
PROG_LIBDIRS_acqctl := proto daemon/plan config

# Debian packages the build, the tests and the demo need (the `deps` step installs the missing ones).
DEB_PKGS   := build-essential pkg-config libusb-1.0-0-dev libmodbus-dev libserialport-dev libsqlite3-dev \
              libyaml-dev liblapacke-dev libopenblas-dev libsystemd-dev libcmocka-dev libpng-dev \
              libjansson-dev libcairo2-dev umockdev mbpoll python3-pymodbus python3-numpy sqlite3 socat \
              systemd clang python3-matplotlib libopenexr-dev openexr libhdf5-dev hdf5-tools python3-h5py \
              python3-jsonschema scdoc man-db \
              python3-scipy

.DEFAULT_GOAL := all
.SECONDARY:
.PHONY: all deps check check-unit check-integration check-fuzz demo bench fuzz soak install install-files man uninstall clean \
        test-programs distclean FORCE

-include $(wildcard */module.mk)

define lib_srcs
$(filter-out %_main.c,$(wildcard $(1)/*.c) $(EXTRA_SRCS_$(1)))
endef
define lib_objs
$(patsubst %.c,$(BUILD)/obj/%.o,$(call lib_srcs,$(1)))
endef

define lib_of
$(BUILD)/lib$(notdir $(1)).a
endef
LIBS       := $(foreach d,$(LIBDIRS),$(if $(strip $(call lib_srcs,$(d))),$(call lib_of,$(d))))
MAIN_SRCS  := $(foreach d,$(LIBDIRS),$(wildcard $(d)/*_main.c))
PROGRAMS   := $(foreach s,$(MAIN_SRCS),$(BUILD)/$(subst _,-,$(patsubst %_main.c,%,$(notdir $(s)))))
UNIT_SRCS  := $(wildcard tests/unit/test_*.c)
UNIT_TESTS := $(patsubst tests/unit/%.c,$(BUILD)/tests/%,$(UNIT_SRCS))
BENCH_SRCS := $(wildcard tests/bench/bench_*.c)
BENCHES    := $(patsubst tests/bench/%.c,$(BUILD)/bench/%,$(BENCH_SRCS))
FUZZ_SRCS  := $(wildcard tests/fuzz/fuzz_*.c)
FUZZ_REPLAY:= $(patsubst tests/fuzz/%.c,$(BUILD)/fuzz-replay/%,$(FUZZ_SRCS))
FUZZERS    := $(patsubst tests/fuzz/%.c,$(BUILD)/fuzz/%,$(FUZZ_SRCS))
ALL_OBJS   := $(foreach d,$(LIBDIRS),$(call lib_objs,$(d))) $(patsubst %.c,$(BUILD)/obj/%.o,$(MAIN_SRCS))

all: $(PROGRAMS)

test-programs: $(PROGRAMS) $(UNIT_TESTS) $(FUZZ_REPLAY) $(EXTRA_TEST_PROGRAMS)

# ---- compile and link -----------------------------------------------------------------------------
$(BUILD)/obj/%.o: %.c $(BUILD)/.cflags | $(BUILD)/gen/acq_version.h
	@mkdir -p $(dir $@)
	@$(if $(Q),echo "  CC      $<")
	$(Q)$(CC) $(ALL_CFLAGS) -c $< -o $@

# The version string and the installed data directory (help texts name the installed schema) live in a generated
# header, rewritten only when they change (#include "acq_version.h").
ACQ_GEN_H = '\#define ACQ_VERSION "$(VERSION)"\n\#define ACQ_DATADIR "$(DATADIR)"\n'
$(BUILD)/gen/acq_version.h: FORCE
	@mkdir -p $(dir $@)
	@printf $(ACQ_GEN_H) | cmp -s - $@ || printf $(ACQ_GEN_H) > $@

# Rebuild everything when the flags change (e.g. SANITIZE or CFLAGS on the command line).
$(BUILD)/.cflags: FORCE
	@mkdir -p $(BUILD)
	@echo '$(CC) $(ALL_CFLAGS) $(LDFLAGS)' | cmp -s - $@ || echo '$(CC) $(ALL_CFLAGS) $(LDFLAGS)' > $@
FORCE: # phony (.PHONY above): under .SECONDARY a missing prerequisite without a recipe never forced a rebuild, so the version header and the flags stamp went stale

define lib_rule
$(call lib_of,$(1)): $(call lib_objs,$(1))
	@rm -f $$@
	$(Q)$(AR) rcs $$@ $$^
endef
$(foreach d,$(LIBDIRS),$(eval $(call lib_rule,$(d))))

prog_name = $(subst _,-,$(patsubst %_main.c,%,$(notdir $(1))))
prog_libs = $(if $(PROG_LIBDIRS_$(call prog_name,$(1))),$(foreach d,$(PROG_LIBDIRS_$(call prog_name,$(1))),$(call lib_of,$(d))),$(LIBS))
# A program may have its own files beside its entry point: <folder>/<name>/*.c for <folder>/<name>_main.c
# (e.g. recon/brdf_recon/: command handlers of brdf-recon), linked before the libraries.
define prog_rule
$(BUILD)/$(call prog_name,$(1)): $(patsubst %.c,$(BUILD)/obj/%.o,$(1) $(wildcard $(patsubst %_main.c,%,$(1))/*.c)) $(call prog_libs,$(1))
	@$(if $(Q),echo "  LD      $$@")
	$(Q)$(CC) $(LDFLAGS) -o $$@ $$^ $(LDLIBS)
endef
$(foreach s,$(MAIN_SRCS),$(eval $(call prog_rule,$(s))))

$(BUILD)/tests/%: $(BUILD)/obj/tests/unit/%.o $(LIBS)
	@mkdir -p $(dir $@)
	$(Q)$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

$(BUILD)/bench/%: $(BUILD)/obj/tests/bench/%.o $(LIBS)
	@mkdir -p $(dir $@)
	$(Q)$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)

$(BUILD)/fuzz-replay/%: $(BUILD)/obj/tests/fuzz/%.o $(BUILD)/obj/tests/fuzz/replay_driver.o $(LIBS)
	@mkdir -p $(dir $@)
	$(Q)$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)

# libFuzzer builds (clang), separate objects: the libraries are compiled once (fuzzer-instrumented), each target
# links them.
FUZZ_CFLAGS := -std=c17 -D_GNU_SOURCE -g -O1 -I. -I$(BUILD)/gen $(PKG_CFLAGS) -fsanitize=address,undefined
FUZZ_OBJS  := $(patsubst %.c,$(BUILD)/fuzz-obj/%.o,$(foreach d,$(LIBDIRS),$(call lib_srcs,$(d))))
$(BUILD)/fuzz-obj/%.o: %.c $(BUILD)/gen/acq_version.h
	@mkdir -p $(dir $@)
	$(Q)clang $(FUZZ_CFLAGS) -fsanitize=fuzzer-no-link -c -o $@ $<
$(BUILD)/fuzz/%: tests/fuzz/%.c $(FUZZ_OBJS)
	@mkdir -p $(dir $@)
	clang $(FUZZ_CFLAGS) -fsanitize=fuzzer -o $@ $< $(FUZZ_OBJS) $(LDLIBS)

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)

# ---- dependencies -----------------------------------------------------------------------------------
deps:
	@missing=$$(for p in $(DEB_PKGS); do dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q 'ok installed' || echo $$p; done); \
	if [ -z "$$missing" ]; then exit 0; fi; \
	if [ "$$(id -u)" = 0 ]; then \
	  echo "deps: installing:" $$missing; \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing >/dev/null || \
	  { apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing >/dev/null; }; \
	else \
	  echo "deps: missing Debian packages. Run as root:"; \
	  echo "  apt-get install -y" $$missing; exit 1; \
	fi

# ---- tests ------------------------------------------------------------------------------------------
# ACQ_SEED: the random seed for every test (printed; set it to replay a run).
ifeq ($(origin ACQ_SEED),undefined)
ACQ_SEED := $(shell od -An -N4 -tu4 /dev/urandom | tr -d ' ')
endif
export ACQ_SEED
TEST_ENV := ACQ_BUILD=$(abspath $(BUILD)) ACQ_SRC=$(CURDIR) ACQ_SEED=$(ACQ_SEED) OPENBLAS_NUM_THREADS=1 \
            ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# A sanitized test runs 2-5x slower; on a loaded machine the heavy recon tests left the 300 s wall limit with 41-48 s
# of CPU (session 18, ASan at load 9): twice the limit there (TEST_TIMEOUT on the command line still wins).
ifneq ($(SANITIZE),)
TEST_ENV += TEST_TIMEOUT=$${TEST_TIMEOUT:-600}
endif

check: deps
	@$(MAKE) --no-print-directory test-programs
	@echo "check: seed ACQ_SEED=$(ACQ_SEED) (make check ACQ_SEED=$(ACQ_SEED) replays it)"
	@$(TEST_ENV) tests/run-tests.sh

check-unit: test-programs
	@$(TEST_ENV) tests/run-tests.sh unit

check-integration: test-programs
	@$(TEST_ENV) tests/run-tests.sh integration

check-fuzz: test-programs
	@$(TEST_ENV) tests/run-tests.sh fuzz

# make soak: the daemon under hostile clients while a sweep runs (SOAK_SECONDS, default 1200).
SOAK_SECONDS ?= 1200
soak: $(PROGRAMS)
	@$(TEST_ENV) SOAK_SECONDS=$(SOAK_SECONDS) tests/soak/soak.py

fuzz: $(FUZZERS)
	@$(TEST_ENV) tests/fuzz/run-fuzzers.sh $(FUZZERS)

bench: deps
	@$(MAKE) --no-print-directory all $(BENCHES)
	@$(TEST_ENV) tests/bench/run.sh

demo: deps
	@$(MAKE) --no-print-directory all
	@ACQ_BUILD=$(abspath $(BUILD)) ACQ_SRC=$(CURDIR) tests/demo.sh

# ---- install ----------------------------------------------------------------------------------------
# Man pages from scdoc sources (systemd/man/NAME.SECTION.scd -> build/man/NAME.SECTION).
MAN_SRCS   := $(wildcard systemd/man/*.scd)
MANS       := $(patsubst systemd/man/%.scd,$(BUILD)/man/%,$(MAN_SRCS))
SYSCONFDIR ?= /etc
UDEVDIR    ?= $(PREFIX)/lib/udev
DATADIR    := $(PREFIX)/share/acquisitiond
DOCDIR     := $(PREFIX)/share/doc/acquisitiond
MANDIR     := $(PREFIX)/share/man
COMPDIR    := $(PREFIX)/share/bash-completion/completions
UNITDIR    := $(PREFIX)/lib/systemd/system
DOCS       := README.md recon/reconstruction.md recon/output.md daemon/nexus.md
# Every file `install` writes (uninstall removes exactly these, then the folders that are ours).
INSTALLED  := $(addprefix $(PREFIX)/bin/,$(notdir $(PROGRAMS))) \
              $(foreach m,$(MAN_SRCS),$(MANDIR)/man$(subst .,,$(suffix $(basename $(m))))/$(notdir $(basename $(m)))) \
              $(COMPDIR)/acqctl $(COMPDIR)/acq-sim $(PREFIX)/lib/sysusers.d/acquisitiond.conf \
              $(PREFIX)/lib/tmpfiles.d/acquisitiond.conf $(UNITDIR)/acquisitiond.service \
              $(UDEVDIR)/rules.d/60-avaspec.rules $(SYSCONFDIR)/acquisitiond/acquisitiond.yaml.example

man: $(MANS)

$(BUILD)/man/%: systemd/man/%.scd
	@mkdir -p $(dir $@)
	$(Q)scdoc < $< > $@.tmp && mv $@.tmp $@

install: all
	@$(MAKE) --no-print-directory install-files

# The copy alone (the programs must be built): the install test runs it on a finished build.
install-files: $(MANS)
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(DATADIR)/config $(DESTDIR)$(DOCDIR) \
	           $(DESTDIR)$(MANDIR)/man1 $(DESTDIR)$(MANDIR)/man5 $(DESTDIR)$(MANDIR)/man8 $(DESTDIR)$(COMPDIR) \
	           $(DESTDIR)$(PREFIX)/lib/sysusers.d $(DESTDIR)$(PREFIX)/lib/tmpfiles.d $(DESTDIR)$(UNITDIR) \
	           $(DESTDIR)$(UDEVDIR)/rules.d $(DESTDIR)$(SYSCONFDIR)/acquisitiond
	install -m 755 $(PROGRAMS) $(DESTDIR)$(PREFIX)/bin/
	install -m 644 config/*.yaml $(DESTDIR)$(DATADIR)/config/
	install -m 644 daemon/schema.sql proto/schema/acqctl-replies.schema.json $(DESTDIR)$(DATADIR)/
	install -m 644 $(DOCS) $(DESTDIR)$(DOCDIR)/
	for m in $(MANS); do n=$$(basename $$m); install -m 644 $$m $(DESTDIR)$(MANDIR)/man$${n##*.}/$$n; done
	install -m 644 systemd/acqctl.bash-completion $(DESTDIR)$(COMPDIR)/acqctl
	install -m 644 systemd/acqctl.bash-completion $(DESTDIR)$(COMPDIR)/acq-sim
	install -m 644 systemd/acquisitiond.sysusers $(DESTDIR)$(PREFIX)/lib/sysusers.d/acquisitiond.conf
	install -m 644 systemd/acquisitiond.tmpfiles $(DESTDIR)$(PREFIX)/lib/tmpfiles.d/acquisitiond.conf
	install -m 644 config/bench-real.yaml $(DESTDIR)$(SYSCONFDIR)/acquisitiond/acquisitiond.yaml.example
	sed 's|@BINDIR@|$(PREFIX)/bin|g' systemd/acquisitiond.service > $(DESTDIR)$(UNITDIR)/acquisitiond.service
	install -m 644 systemd/*.rules $(DESTDIR)$(UDEVDIR)/rules.d/
	@echo "installed under $(DESTDIR)$(PREFIX); then: systemd-sysusers; systemd-tmpfiles --create;" \
	      "udevadm control --reload; cp $(SYSCONFDIR)/acquisitiond/acquisitiond.yaml.example" \
	      "$(SYSCONFDIR)/acquisitiond/acquisitiond.yaml (edit it); systemctl enable --now acquisitiond"

# Removes every installed file and our own folders; the operator's /etc/acquisitiond/acquisitiond.yaml and the
# data in /var/lib/acquisitiond are kept.
uninstall:
	rm -f $(addprefix $(DESTDIR),$(INSTALLED))
	rm -rf $(DESTDIR)$(DATADIR) $(DESTDIR)$(DOCDIR)
	-rmdir $(DESTDIR)$(SYSCONFDIR)/acquisitiond 2>/dev/null

clean:
	rm -rf build
