/* cie_tables: embedded CIE colorimetric tables (generated into cie_tables.c by gen_cie_tables.py). */
#ifndef RECON_CIE_TABLES_H
#define RECON_CIE_TABLES_H

#define CIE_CMF_FIRST_NM 360 /* first wavelength of cie_cmf_1931_2deg, 1 nm steps */
#define CIE_CMF_N 471        /* 360..830 nm */
#define CIE_D65_FIRST_NM 300 /* first wavelength of cie_d65_spd, 5 nm steps */
#define CIE_D65_STEP_NM 5
#define CIE_D65_N 107        /* 300..830 nm */

/* x̄, ȳ, z̄ of the CIE 1931 2° standard observer at CIE_CMF_FIRST_NM + i nm. */
extern const double cie_cmf_1931_2deg[CIE_CMF_N][3];

/* Relative spectral power of CIE illuminant D65 at CIE_D65_FIRST_NM + 5 i nm. */
extern const double cie_d65_spd[CIE_D65_N];

#endif
