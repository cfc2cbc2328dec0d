"""The C kernel is compiled when the package installs (cffi, API mode): see kernel_build.py."""
from setuptools import setup

setup(cffi_modules=["kernel_build.py:plant_ffi", "kernel_build.py:controller_ffi",
                      "kernel_build.py:scenarios_ffi"])
