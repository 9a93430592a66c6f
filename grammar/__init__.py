# The Lark grammar of the .frac language, shipped as package data (fractalc.grammar).
