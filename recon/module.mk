# recon/: rbf.c holds the kernel loops of every evaluation; let the compiler vectorise them (sqrt without errno, no FP traps:
# the results are the same bits as the scalar path, see rbf_krow).
$(BUILD)/obj/recon/rbf.o: ALL_CFLAGS += -O3 -fno-math-errno -fno-trapping-math -ffp-contract=off
LDLIBS += -lmvec
