"""Slot numbers of the integrator's plain arrays (parameters, state, modes, recorded channels).

The integrator is compiled with numba and takes only arrays, so every quantity has a fixed slot.
Kept in one small module so that the physics description (`plant`) and the compiled code
(`kernel`) agree without importing each other's internals.
"""

from __future__ import annotations

# --- parameters (float64 vector) -------------------------------------------------------------
M1, M2, K0, C0, K1, C1, K2, C2, DIST = range(9)
ARM_KIND, ARM_TAU, ARM_WN, ARM_ZETA = range(9, 13)
STIFF_FORM, STIFF_B, STIFF_SREF, STIFF_Q = range(13, 17)
ADH_FORM, ADH_F, ADH_RANGE = range(17, 20)
HYS_ON, HYS_ALPHA, HYS_UY, HYS_N = range(20, 24)
BED_FORM, BED_X, BED_K, BED_C, BED_N = range(24, 29)
PRE_FORM, PRE_W, PRE_DELTA, PRE_DAMP = range(29, 33)
LET_FORM, LET_F, LET_X, LET_W, LET_WD = range(33, 38)
FR_FORM, FR_FC, FR_FS, FR_VS, FR_S0, FR_S1, FR_S2 = range(38, 45)
N_PARAMS = 45

# --- continuous state ------------------------------------------------------------------------
X1, V1, X2, V2, XA, VA, ZF, ZH = range(8)
N_STATE = 8

# --- discrete modes (float64 vector so one array type serves all) ----------------------------
TOUCH, STUCK, SLIP_DIR, AT_STOP, DESC, BED_IN = range(6)
N_MODES = 6

# --- recorded channels -----------------------------------------------------------------------
OUT_T, OUT_XC, OUT_XA, OUT_VA, OUT_X1, OUT_V1, OUT_X2, OUT_V2, OUT_FC, OUT_F0 = range(10)
N_OUT = 10
OUT_NAMES = ("t_s", "x_cmd_m", "x0_m", "v0_mps", "x1_m", "v1_mps", "x2_m", "v2_mps",
             "contact_n", "body_n")  # fmt: skip

# --- form codes ------------------------------------------------------------------------------
ARM_EXACT, ARM_LAG, ARM_SERVO, ARM_DELAY = 0, 1, 2, 3
STIFF_NONE, STIFF_EXP, STIFF_POWER = 0, 1, 2
ADH_NONE, ADH_PULL_OFF, ADH_COHESIVE = 0, 1, 2
BED_NONE, BED_LINEAR, BED_HC15, BED_POWER = 0, 1, 2, 3
PRE_NONE, PRE_REST_STOP, PRE_FELT = 0, 1, 2
LET_NONE, LET_GAUSS, LET_TRIP = 0, 1, 2
FR_NONE, FR_STRIBECK, FR_LUGRE = 0, 1, 2

BED_REF_M = 1e-3  # reference indentation of the Hunt–Crossley and power-law stops
