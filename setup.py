"""The one compiled part of PLE: an optional binary STL encoder (``ple.io._stlcodec``). Without a C
compiler the build skips it and ``ple.io.export`` encodes with numpy (the same bytes, slower)."""

from setuptools import Extension, setup

setup(ext_modules=[Extension("ple.io._stlcodec", ["core/ple/io/_stlcodec.c"], optional=True,
                             extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"])])
