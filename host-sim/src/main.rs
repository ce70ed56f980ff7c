//! `shimmy-sim`: the simulator's command-line tool.
use shimmy_core::params::{Param, ParamSet};

fn main() {
    // TODO(issue 3/7): the simulator proper. Until then print the named parameter sets.
    println!("shimmy-sim {}: parameter sets", shimmy_core::VERSION);
    for set in ParamSet::ALL {
        let p = set.params();
        println!("[{}]", set.name());
        for q in Param::ALL {
            println!("  {:<6} = {:>12.6} {}", q.name(), p.get(q), q.unit());
        }
    }
}
