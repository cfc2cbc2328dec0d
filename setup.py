"""The C kernel is compiled when the package installs (cffi, API mode): see kernel_build.py.
An editable install also byte-compiles the packages in place: where PYTHONDONTWRITEBYTECODE
is set (as on the kit's CI machine), every `movingbase` process would otherwise compile its
~50 modules from source again (0.08 s of a 1.5 s run's CPU)."""
import compileall
import pathlib

from setuptools import setup
from setuptools.command.build_ext import build_ext

HERE = pathlib.Path(__file__).parent


class BuildExtThenByteCompile(build_ext):
    def run(self):
        super().run()
        if self.inplace:   # a wheel is byte-compiled by the installer instead
            for package in sorted({name.split(".")[0] for name in self.distribution.packages}):
                compileall.compile_dir(str(HERE / package), quiet=1)


setup(cffi_modules=["kernel_build.py:plant_ffi", "kernel_build.py:controller_ffi",
                      "kernel_build.py:scenarios_ffi"],
      cmdclass={"build_ext": BuildExtThenByteCompile})
