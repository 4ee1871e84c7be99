//! Finding the feedback loops of a graph: the strongly connected components of
//! its block graph (an edge from each block to every block reading one of its
//! outputs). A component with more than one block, or a block reading its own
//! output, holds at least one feedback loop; blocks of one component are analysed
//! together, so nested loops (an inner loop inside an outer one) are one loop of
//! the report, closed as a whole.

/// The strongly connected components of the graph with `succ[i]` the successors
/// of node i that hold a cycle, each sorted, in order of their smallest node
/// (Kosaraju's algorithm, iterative).
pub(crate) fn cyclic_components(succ: &[Vec<usize>]) -> Vec<Vec<usize>> {
    let n = succ.len();
    // Pass 1: finishing order of a depth-first search.
    let mut seen = vec![false; n];
    let mut order = Vec::with_capacity(n);
    for start in 0..n {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let mut stack = vec![(start, 0usize)];
        while let Some(&mut (v, ref mut next)) = stack.last_mut() {
            if let Some(&w) = succ[v].get(*next) {
                *next += 1;
                if !seen[w] {
                    seen[w] = true;
                    stack.push((w, 0));
                }
            } else {
                order.push(v);
                stack.pop();
            }
        }
    }
    // Pass 2: on the reversed graph, in reverse finishing order.
    let mut pred = vec![Vec::new(); n];
    for (v, ws) in succ.iter().enumerate() {
        for &w in ws {
            pred[w].push(v);
        }
    }
    let mut comp = vec![usize::MAX; n];
    let mut comps: Vec<Vec<usize>> = Vec::new();
    for &root in order.iter().rev() {
        if comp[root] != usize::MAX {
            continue;
        }
        let id = comps.len();
        let mut members = vec![root];
        comp[root] = id;
        let mut stack = vec![root];
        while let Some(v) = stack.pop() {
            for &w in &pred[v] {
                if comp[w] == usize::MAX {
                    comp[w] = id;
                    members.push(w);
                    stack.push(w);
                }
            }
        }
        members.sort_unstable();
        comps.push(members);
    }
    let mut cyclic: Vec<Vec<usize>> = comps
        .into_iter()
        .filter(|c| c.len() > 1 || succ[c[0]].contains(&c[0]))
        .collect();
    cyclic.sort_by_key(|c| c[0]);
    cyclic
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_loops_and_ignores_chains() {
        // 0 -> 1 -> 2 -> 1 (loop {1, 2}); 2 -> 3 (chain); 4 -> 4 (self-loop);
        // 5 -> 6 -> 7 -> 5 (loop).
        let succ = vec![
            vec![1],
            vec![2],
            vec![1, 3],
            vec![],
            vec![4],
            vec![6],
            vec![7],
            vec![5],
        ];
        assert_eq!(
            cyclic_components(&succ),
            vec![vec![1, 2], vec![4], vec![5, 6, 7]]
        );
        assert!(cyclic_components(&[vec![1], vec![2], vec![]]).is_empty());
    }
}
