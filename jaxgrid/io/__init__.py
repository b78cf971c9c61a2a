"""Readers for PSS/E RAW and DYR files and MATPOWER case data.

They stand on the case tables (`jaxgrid.case`), the DYR record types (`jaxgrid.records`) and
the input checks (`jaxgrid.checks`) only; the PNNL study JSON is read in `jaxgrid.study.pnnl`.
"""
