#!/usr/bin/env python3
"""Self-test of scripts/check-modules: it runs the checker on fake workspaces in a temp dir.

- crates/good is acyclic but full of things a naive checker trips on: a `mod.rs` facade whose
  child reaches a sibling through it (`use super::GpParams`, `crate::gp::GpParams`) while the
  facade calls that child; a facade re-exporting a child that implements its trait; a root
  re-export (`crate::Error`), nested multi-line `use crate::{a::{self, b}, c::{d as e}}` groups,
  and cyclic-looking paths in doc comments, block comments, strings and `#[cfg(test)]` code
  (a mid-file test `impl`, with a '{' char literal, must not hide the code after it);
  also a src/bin/ root that is skipped. It must pass.
- crates/bad has a real cycle x -> y -> x, made on one side by an inline `crate::x::f()` path in
  code. It must fail with exit code 1 and name both edges with their file and line.
Run: python3 scripts/check_modules_selftest.py  (prints "ok", or fails an assertion)
"""
import subprocess
import sys
import tempfile
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent / 'check-modules'

GOOD = {
    'Cargo.toml': '[package]\nname = "good"\nversion = "0.1.0"\n',
    'src/lib.rs': '''\
//! The crate. See [`crate::kernel::k`] and [`crate::util`].
pub mod gp;
pub mod kernel;
pub mod shape;
pub mod util;
mod error;

pub use error::Error;
''',
    'src/error.rs': 'pub struct Error;\n',
    'src/gp/mod.rs': '''\
//! Facade: the items live in the children.
mod params;
mod prepared;

pub use params::GpParams;
pub use prepared::Prepared;

use crate::kernel::k;

pub fn fit() -> f64 {
    k() + prepared::size()
}
''',
    'src/gp/params.rs': '''\
use crate::Error;

pub struct GpParams;

pub fn check() -> Result<(), Error> {
    Ok(())
}
''',
    'src/gp/prepared.rs': '''\
use super::GpParams;

pub struct Prepared(pub GpParams, pub crate::gp::GpParams);

pub fn size() -> f64 {
    2.0
}
''',
    'src/shape/mod.rs': '''\
mod circle;

pub use circle::Circle;

pub trait Shape {}
''',
    'src/shape/circle.rs': 'use super::Shape;\n\npub struct Circle;\n\nimpl Shape for Circle {}\n',
    'src/kernel.rs': '''\
/// Unlike [`crate::gp::Prepared`], a kernel knows nothing of `crate::util::helper`.
/* A block comment /* nested */ calling crate::gp::fit() */
pub fn k() -> f64 {
    let _label = "crate::gp::GpParams";
    1.0
}

#[cfg(test)]
impl Helper {
    fn probe() -> char {
        crate::gp::fit();
        '{'
    }
}

pub fn after_the_test_impl() -> Option<crate::error::Error> {
    None
}

#[cfg(test)]
mod tests {
    use crate::gp::GpParams;
    use crate::util::helper;
}
''',
    'src/util.rs': '''\
use crate::{
    kernel::{self, k},
    gp::{GpParams as G, Prepared},
};
pub(crate) use crate::Error as E;

pub fn helper(_: &G, _: &Prepared) -> Result<f64, E> {
    Ok(k() + kernel::k())
}
''',
    'src/bin/tool.rs': 'fn main() { good::util::helper(); }\n',
}

BAD = {
    'Cargo.toml': '[package]\nname = "bad"\nversion = "0.1.0"\n',
    'src/main.rs': 'mod x;\nmod y;\n\nfn main() {\n    x::f();\n}\n',
    'src/x.rs': 'use crate::y::g;\n\npub fn f() {\n    g()\n}\n',
    'src/y.rs': 'pub fn g() {\n    if false {\n        crate::x::f()\n    }\n}\n',
}


def write(root, files):
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def run(root, *args):
    p = subprocess.run([sys.executable, str(SCRIPT), '--root', str(root), *args],
                       capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def main():
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        write(root / 'crates/good', GOOD)
        code, out = run(root)
        assert code == 0, out
        assert out.strip() == 'good: 9 files, 5 top-level modules, no cycle', out

        write(root / 'crates/bad', BAD)
        (root / 'benches').mkdir()  # no Cargo.toml: not a crate
        code, out = run(root)
        assert code == 1, out
        assert 'good: 9 files, 5 top-level modules, no cycle' in out, out
        assert 'bad: 3 files, 2 top-level modules, 1 file-level and 1 concept-level cycles' in out, out
        assert 'concept-level cycle among x, y' in out, out
        assert 'x -> y: crates/bad/src/x.rs:1 crate::y::g' in out, out
        assert 'y -> x: crates/bad/src/y.rs:3 crate::x::f' in out, out
        assert 'crates/good' not in out, out  # no spurious edge from the good crate

        assert run(root, '--crate', 'good')[0] == 0
        assert run(root, '--crate', 'bad')[0] == 1
        assert run(root, '--crate', 'none')[0] == 2
        code, dot = run(root, '--dot', '--crate', 'bad')
        assert code == 0 and dot.startswith('digraph "bad" {'), dot
        assert '"x" -> "y" [color=red];' in dot and '"y" -> "x" [color=red];' in dot, dot
        code, dot = run(root, '--dot', '--crate', 'good')
        assert '"gp" -> "kernel";' in dot and '"util" -> "gp";' in dot and 'red' not in dot, dot
        assert '"kernel" -> "gp"' not in dot and '"gp" -> "error"' in dot, dot
        assert '"kernel" -> "error"' in dot, dot  # code after a mid-file #[cfg(test)] item counts
    print('ok')


if __name__ == '__main__':
    main()
