"""Build of the C extension only; metadata lives in pyproject.toml.

MARIONETTE_DEBUG=1     -O0 -g, asserts on
MARIONETTE_SANITIZE=1  AddressSanitizer + UndefinedBehaviorSanitizer (run
                       Python with LD_PRELOAD=$(gcc -print-file-name=libasan.so))
"""
import os
from glob import glob

import numpy
from Cython.Build import cythonize
from setuptools import Extension, setup

debug = os.environ.get("MARIONETTE_DEBUG") == "1"
sanitize = os.environ.get("MARIONETTE_SANITIZE") == "1"

compile_args = ["-std=c11", "-Wall", "-Wextra", "-fno-strict-aliasing"]
link_args = ["-lpthread", "-lm"]
compile_args += ["-O0", "-g"] if debug else ["-O2"]
if sanitize:
    flags = ["-fsanitize=address,undefined", "-fno-omit-frame-pointer"]
    compile_args += flags
    link_args += flags



def extension(name: str, pyx: str, c_sources: list[str]) -> Extension:
    return Extension(
        name,
        sources=[pyx] + c_sources,
        include_dirs=["ext", "firmware_protocol", numpy.get_include()],
        define_macros=[("_POSIX_C_SOURCE", "200809L"), ("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")]
        + ([] if debug else [("NDEBUG", None)]),
        extra_compile_args=compile_args,
        extra_link_args=link_args,
    )


extensions = [
    # the tick engine and everything it runs
    extension("marionette._core", "marionette/_core.pyx",
              sorted(set(glob("ext/*.c")) - {"ext/mar_shape.c"}) + sorted(glob("firmware_protocol/*.c"))),
    # the offline pragmatic filter (timed parabolic moves between extrema)
    extension("marionette._shape", "marionette/_shape.pyx", ["ext/mar_shape.c"]),
    # the music follower (ext/mar_follow*.c), for offline tools and tests (the engine links its own copy)
    extension("marionette._follow", "marionette/_follow.pyx", sorted(glob("ext/mar_follow*.c"))),
    # the servo protocol codec, for the simulator, the transports and the tests
    extension("marionette._protocol", "marionette/_protocol.pyx", sorted(glob("firmware_protocol/*.c"))),
]

setup(ext_modules=cythonize(extensions, compiler_directives={"language_level": "3"}))
