"""Sub-commands of ``ple``; every module here is discovered by ``ple.cli``."""
