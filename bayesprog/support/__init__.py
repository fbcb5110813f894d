"""What every layer stands on, and none of them is about: files written whole and the file
kinds a command reads (:mod:`~bayesprog.support.files`), the checked programs kept between
processes (:mod:`~bayesprog.support.cache`), the bundled models found by name
(:mod:`~bayesprog.support.bundled`), program files as YAML text
(:mod:`~bayesprog.support.yamltext`), the optional extras and the names imported at their
first use (:mod:`~bayesprog.support.extras`), the old paths of the modules that moved
(:mod:`~bayesprog.support.moved`), and the notebook display's hooks
(:mod:`~bayesprog.support.rich`).

It imports nothing of bayesprog but its errors and size limits (:mod:`bayesprog.errors`,
:mod:`bayesprog.limits`).
"""
