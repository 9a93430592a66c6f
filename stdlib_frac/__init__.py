# Formulas written in the .frac language, shipped as package data (fractalc.stdlib_frac): docs/formulas.md.
