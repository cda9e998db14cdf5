"""The compiled parts of PLE, both optional: a binary STL encoder (``ple.io._stlcodec``) and box
assembly (``ple.meshing._assemble``). Without a C compiler the build skips them and
``ple.io.export`` and ``ple.meshing.tessellate`` use numpy (the same bytes, slower)."""

from setuptools import Extension, setup

FLAGS = ["-O2", "-ffp-contract=off", "-fno-fast-math"]  # IEEE operations as written: the numpy forms' values

setup(ext_modules=[Extension("ple.io._stlcodec", ["core/ple/io/_stlcodec.c"], optional=True, extra_compile_args=FLAGS),
                   Extension("ple.meshing._assemble", ["core/ple/meshing/_assemble.c"], optional=True,
                             extra_compile_args=FLAGS)])
