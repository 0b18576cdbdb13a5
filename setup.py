"""The package list of pyproject.toml's layout (the folders fmus/, observers/, plants/ installed as obsfmu.*):
setuptools cannot discover subpackages of a mapped folder from pyproject.toml alone."""

from setuptools import find_packages, setup

FOLDERS = ("fmus", "observers", "plants")

setup(packages=["obsfmu"] + [f"obsfmu.{name}" for folder in FOLDERS
                             for name in [folder] + [f"{folder}.{sub}" for sub in find_packages(folder)]])
