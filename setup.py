"""The compiled parts of PLE, all optional: a binary STL encoder (``ple.io._stlcodec``), box
assembly (``ple.meshing._assemble``), the self-intersection check (``ple.meshing._selfcheck``) and
the pulled-back BIQ (``ple.queries._rangefinder``). Without a C compiler the build skips them and
``ple.io.export``, ``ple.meshing.tessellate``, ``ple.meshing.selfcheck`` and
``ple.queries.pullback`` use numpy (the same results, slower)."""

from setuptools import Extension, setup

FLAGS = ["-O2", "-ffp-contract=off", "-fno-fast-math"]  # IEEE operations as written: the numpy forms' values

setup(ext_modules=[Extension("ple.io._stlcodec", ["core/ple/io/_stlcodec.c"], optional=True, extra_compile_args=FLAGS),
                   Extension("ple.meshing._assemble", ["core/ple/meshing/_assemble.c"], optional=True,
                             extra_compile_args=FLAGS),
                   Extension("ple.meshing._selfcheck", ["core/ple/meshing/_selfcheck.c"], optional=True,
                             extra_compile_args=FLAGS),
                   Extension("ple.queries._rangefinder", ["core/ple/queries/_rangefinder.c"], optional=True,
                             extra_compile_args=FLAGS)])
