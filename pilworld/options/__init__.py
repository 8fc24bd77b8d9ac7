"""What a user may type as an option value, parsed and checked once for every command.

Shared by the command line (:mod:`pilworld.cli`) and the benches' ``run(args)`` (:mod:`pilworld.bench`),
which sits below it: neither may own these for the other.
"""
