# CLI contract: --help everywhere, one-line errors with exit code 2, check passes and fails
# as it should, bench writes the CSV header of docs/benchmarks.md, "Protocol".
include(${CMAKE_CURRENT_LIST_DIR}/cli_helpers.cmake)

foreach(sub "" methods check bench generate neighbours)
  expect_exit(0 ${sub} --help)
  expect_match("${last_out}" "Usage")
endforeach()

expect_exit(0 methods)
expect_match("${last_out}" "cell-list +available")

# Bad usage: one line, exit 2.
expect_exit(2 check --methods no-such-method)
expect_match("${last_err}" "unknown method 'no-such-method'")
expect_exit(2 check --family no-such-family)
expect_match("${last_err}" "unknown input family")
expect_exit(2 check -n many)
expect_exit(2 bench --kernel gravity)
expect_exit(2 check --input ${WORK}/missing.csv)
expect_exit(2)

# A malformed file names its line.
file(WRITE ${WORK}/bad.csv "x,y,z\n0,0,0\n1,2\n")
expect_exit(2 check --input ${WORK}/bad.csv --cutoff 1)
expect_match("${last_err}" "bad.csv:3")

# A NaN in a file names the particle index.
file(WRITE ${WORK}/nan.csv "0,0,0\n0.5,0.5,0.5\n1,nan,1\n")
expect_exit(2 check --input ${WORK}/nan.csv --cutoff 1 --methods cell-list)
expect_match("${last_err}" "index 2")

# check passes on families and on a generated file.
expect_exit(0 check --methods cell-list --family lattice-k1,coincident,diagonal -n 0,1,300)
expect_match("${last_out}" "passed: 0 mismatch")
expect_exit(0 generate --family uniform -n 500 --out ${WORK}/cloud.xyz)
expect_exit(0 check --methods cell-list --input ${WORK}/cloud.xyz --cutoff 1)
expect_match("${last_out}" "cloud.xyz|ok")

# bench writes the protocol's CSV.
expect_exit(0 bench --suite uniform --methods cell-list --param 4 --p 1,2 --reps 2 --out ${WORK}/b.csv)
file(READ ${WORK}/b.csv csv)
expect_match("${csv}" "^suite,method,param,p,N,cutoff,pairs,build_ms,compute_ms,total_ms,total_ms_min,total_ms_max,reps,timer,gpu,driver,cuda,optix\n")
expect_match("${csv}" "uniform,cell-list,4,2,128,")
# --large-n / --large-reps: the reps column says how many repetitions were timed.
expect_exit(0 bench --suite uniform --methods cell-list --param 4 --p 1,2 --reps 3 --large-n 100
            --large-reps 1 --out ${WORK}/l.csv)
file(READ ${WORK}/l.csv csv)
expect_match("${csv}" "uniform,cell-list,4,1,64,[^\n]*,3,host,")
expect_match("${csv}" "uniform,cell-list,4,2,128,[^\n]*,1,host,")

# --paper-binary runs the given program in a scratch folder and merges its results-*.csv.
file(WRITE ${WORK}/fake_paper.sh "#!/bin/sh\nprintf 'NbParticles,NbInteractions,NbLoops,boxDiv,nbCells,partspercell,interactionsperparticle,timeinit,timecompute,timetotal\\n64,1,5,4,64,1,1,0.001,0.002,0.003\\n64,1,5,4,64,1,1,0.003,0.002,0.005\\n' > results-test.csv\n")
file(CHMOD ${WORK}/fake_paper.sh PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE)
expect_exit(0 bench --methods cell-list --param 4 --p 1 --reps 1 --out ${WORK}/m.csv --paper-binary ${WORK}/fake_paper.sh)
file(READ ${WORK}/m.csv csv)
expect_match("${csv}" "uniform,paper-cudaLJ,4,1,64,0.25,,2.0000,2.0000,4.0000,3.0000,5.0000,2,host,")
# Hostile options, inputs and outputs give one-line errors naming what is wrong, exit 2.
expect_exit(2 no-such-subcommand)
expect_match("${last_err}" "unknown subcommand 'no-such-subcommand'")
expect_exit(2 check -n -1 -m cell-list -f uniform)
expect_match("${last_err}" "--n: must be a whole number >= 0, got '-1'")
expect_exit(2 check -n 1000000000000000 -m cell-list -f uniform)
expect_match("${last_err}" "out of memory: .*needs .* of host memory, .* is available")
foreach(bad 0 0.1abc nan -2)  # 1e39: a range refusal (test_cli_limits.cmake)
  expect_exit(2 check --cutoff ${bad})
  expect_match("${last_err}" "cutoff: must be a finite number > 0, got '${bad}'")
endforeach()
expect_exit(2 check --oracle cell-list)
expect_match("${last_err}" "one of auto, brute-force, brute-force-gpu")
expect_exit(2 generate --cutoff 3e38 -n 10 -o ${WORK}/inf.xyz)
expect_match("${last_err}" "non-finite coordinates")
expect_exit(2 generate --suite uniform --param 4194304 -o ${WORK}/big.xyz)
expect_match("${last_err}" "p \\* param\\^3")
if(EXISTS ${WORK}/inf.xyz OR EXISTS ${WORK}/big.xyz)
  message(FATAL_ERROR "a refused generate left a file")
endif()
# The README's form (-f), and the extension in any case.
expect_exit(0 generate -f lattice-k1 -n 8 -o ${WORK}/upper.CSV)
file(READ ${WORK}/upper.CSV csv)
expect_match("${csv}" "^x,y,z\n")
expect_exit(2 generate -n 8 -o ${WORK}/points.txt)
expect_match("${last_err}" "unknown extension '.txt'")
# A one-line CSV without a header is one particle, not a header.
file(WRITE ${WORK}/one.csv "0.5,0.5,0.5\n")
expect_exit(0 check -m cell-list -i ${WORK}/one.csv -c 1)
expect_match("${last_out}" "one.csv +1 ")

# Outputs: a full device or an unwritable folder is an error naming the path, never "wrote"
# with exit 0; a missing folder fails before the run; no temporary file is left behind.
if(EXISTS /dev/full)
  expect_exit(2 bench --methods cell-list --param 4 --p 1 --reps 1 --out /dev/full)
  expect_match("${last_err}" "/dev/full: write failed: No space left on device")
  expect_exit(2 update-bench --methods cell-list --param 2 --p 1 --steps 1 --out /dev/full)
  expect_match("${last_err}" "/dev/full: write failed")
  file(CREATE_LINK /dev/full ${WORK}/full.xyz SYMBOLIC)
  expect_exit(2 generate -n 10 -o ${WORK}/full.xyz)
  expect_match("${last_err}" "full.xyz: write failed")
endif()
expect_exit(2 bench --methods cell-list --param 4 --p 1 --reps 1 --out ${WORK}/missing/b.csv)
expect_match("${last_err}" "missing/b.csv: cannot write in")
if(last_err MATCHES "done")
  message(FATAL_ERROR "bench ran before finding its output unwritable:\n${last_err}")
endif()
expect_exit(2 generate -n 10 -o ${WORK}/missing/g.csv)
expect_match("${last_err}" "missing/g.csv: cannot write in")
file(GLOB leftovers ${WORK}/.*.tmp-*)
if(leftovers)
  message(FATAL_ERROR "temporary files left behind: ${leftovers}")
endif()

# Periodic boxes. --cell (9 numbers, or 3 for an orthorhombic box) and --pbc, as
# separate values or one quoted string; each method against the brute force in the same box.
# Boxes thinner than 2 cutoffs: pairs once per image, self-images.
expect_exit(0 check -m cell-list -f uniform,lattice-k1,coincident -n 0,1,150 --cell 1.5 1.5 1.5)
expect_match("${last_out}" "periodic box 1.5x1.5x1.5 \\(pbc T T T\\)")
expect_match("${last_out}" "passed: 0 mismatch")
expect_exit(0 check -m cell-list -f uniform -n 200 --cell "2 0 0 0.7 2 0 -0.3 0.4 2" --pbc "T F T")
expect_match("${last_out}" "\\[\\[2 0 0\\] \\[0.7 2 0\\] \\[-0.3 0.4 2\\]\\] \\(pbc T F T\\)")
expect_match("${last_out}" "passed: 0 mismatch")
expect_exit(0 check -m cell-list -f uniform -n 200 --cell 1 0 0 -0.5 0.8 0 0 0 1 --pbc 1 1 0)
expect_match("${last_out}" "passed: 0 mismatch")
# A periodic extended-XYZ file is checked in its box. One particle in a unit cube at cutoff 1.5:
# its 6 face and 12 edge images (|S| = 1, 1.41), not the 8 corners (1.73).
file(WRITE ${WORK}/self.xyz "1\nLattice=\"1 0 0 0 1 0 0 0 1\" Properties=species:S:1:pos:R:3 pbc=\"T T T\"\nH 0.3 0.4 0.5\n")
expect_exit(0 check -m cell-list -i ${WORK}/self.xyz -c 1.5)
expect_match("${last_out}" "self.xyz +1 +1.5 +cell-list +18 +0 ")
expect_match("${last_out}" "passed: 0 mismatch")
# Two particles 1.8 apart, 0.2 through the periodic x face (pbc T F F): 2 entries; with --pbc
# F F F (overriding the file's) none. Lattice without pbc is periodic on every axis (ASE).
file(WRITE ${WORK}/pair.xyz "2\nLattice=\"2 0 0 0 2 0 0 0 2\" Properties=species:S:1:pos:R:3 pbc=\"T F F\"\nH 0.1 0.1 0.1\nH 1.9 0.1 0.1\n")
expect_exit(0 check -m cell-list -i ${WORK}/pair.xyz -c 0.5)
expect_match("${last_out}" "pair.xyz +2 +0.5 +cell-list +2 +0 ")
expect_exit(0 check -m cell-list -i ${WORK}/pair.xyz -c 0.5 --pbc F F F)
expect_match("${last_out}" "pair.xyz +2 +0.5 +cell-list +0 +0 ")
file(WRITE ${WORK}/lattice.xyz "2\nLattice=\"2 0 0 0 2 0 0 0 2\"\nH 0.1 0.1 0.1\nH 0.1 1.9 1.9\n")
expect_exit(0 check -m cell-list -i ${WORK}/lattice.xyz -c 0.5)
expect_match("${last_out}" "lattice.xyz +2 +0.5 +cell-list +2 +0 ")
# --cell overrides the file's cell (here: too wide for the image).
expect_exit(0 check -m cell-list -i ${WORK}/pair.xyz -c 0.5 --cell 3 3 3)
expect_match("${last_out}" "pair.xyz +2 +0.5 +cell-list +0 +0 ")
# A family too large for the box (too many images) is a row saying so; the others are checked.
expect_exit(0 check -m cell-list -f huge-scale,uniform -n 100 --cell 0.7 0.9 1.3)
expect_match("${last_out}" "huge-scale +100 .* brute-force +- +- +- +refused")
expect_match("${last_out}" "passed: 0 mismatch.*1 input\\(s\\) refused")
expect_exit(2 check -m cell-list -f huge-scale -n 100 --cell 0.7 0.9 1.3)
expect_match("${last_err}" "every input was refused")
# Bad values: exit 2, one line naming the option; a singular cell gets the box's message.
foreach(bad "1 2" "1 2 3 4" "1 2 x" "1 2 nan" "1 2 3 4 5 6 7 8 1e999")
  expect_exit(2 check -m cell-list -f uniform -n 10 --cell ${bad})
  expect_match("${last_err}" "--cell: must be 9 finite numbers")
endforeach()
expect_exit(2 check -m cell-list -f uniform -n 10 --cell 1 0 0 2 0 0 0 0 1)
expect_match("${last_err}" "--cell: .*linearly dependent")
expect_exit(2 check -m cell-list -f uniform -n 10 --cell 0 1 1)
expect_match("${last_err}" "--cell: .*zero length")
foreach(bad "T X T" "T T" "yes")
  expect_exit(2 check -m cell-list -f uniform -n 10 --cell 2 2 2 --pbc ${bad})
  expect_match("${last_err}" "--pbc: must be 3 of T/F")
endforeach()
expect_exit(2 check -m cell-list -f uniform -n 10 --pbc T T T)
expect_match("${last_err}" "--pbc: needs a cell")
expect_exit(2 check -m cell-list -i ${WORK}/cloud.xyz --pbc T T T)
expect_match("${last_err}" "--pbc: needs a cell")
expect_exit(2 bench --methods cell-list --param 4 --p 1 --cell 1 1)
expect_match("${last_err}" "--cell: must be 9 finite numbers")
# bench in a box: its rows under the suite name with -periodic.
expect_exit(0 bench --methods cell-list --param 4 --p 1,2 --reps 1 --cell 1 1 1 --out ${WORK}/p.csv)
file(READ ${WORK}/p.csv csv)
expect_match("${csv}" "uniform-periodic,cell-list,4,2,128,")
# Methods without periodic boxes (grid-paper, OptiX) are rows saying so, not mismatches; with
# nothing left to compare, exit 2.
expect_exit(0 methods)
if(last_out MATCHES "grid-paper +available")
  expect_exit(0 check -m cell-list,grid-paper -f uniform -n 100 --cell 2 2 2)
  expect_match("${last_out}" "grid-paper +- +- +- +unsupported")
  expect_match("${last_out}" "passed: 0 mismatch.*1 skipped")
  expect_exit(2 check -m grid-paper -f uniform -n 100 --cell 2 2 2)
  expect_match("${last_err}" "none of the methods")
endif()

# --version: the project's version.
expect_exit(0 --version)
expect_match("${last_out}" "^raycut [0-9]+\\.[0-9]+\\.[0-9]+")

# neighbours: the list of a file, with ASE's letters. Two particles 0.6 apart in a periodic unit
# cube at cutoff 0.5: one pair through the boundary each way (S = -1 and +1 along x).
file(WRITE ${WORK}/two.xyz "2\nLattice=\"1 0 0 0 1 0 0 0 1\" Properties=species:S:1:pos:R:3 pbc=\"T T T\"\nH 0.2 0.5 0.5\nH 0.8 0.5 0.5\n")
expect_exit(0 neighbours -m cell-list -i ${WORK}/two.xyz -c 0.5 -o ${WORK}/two.csv --quantities ijS)
file(READ ${WORK}/two.csv csv)
expect_match("${csv}" "^i,j,Sx,Sy,Sz\n0,1,-1,0,0\n1,0,1,0,0\n$")
expect_exit(0 neighbours -m cell-list -i ${WORK}/two.xyz -c 0.5 -o ${WORK}/half.csv --quantities ijd --half)
file(READ ${WORK}/half.csv csv)
expect_match("${csv}" "^i,j,d\n0,1,0\\.(4|39999)[0-9]*\n$")  # 0.4 within a float32 ulp
# Open along x (--pbc): no pair.
expect_exit(0 neighbours -i ${WORK}/two.xyz -c 0.5 -o ${WORK}/open.csv --pbc F T T)
file(READ ${WORK}/open.csv csv)
expect_match("${csv}" "^i,j,d,Dx,Dy,Dz,Sx,Sy,Sz\n$")
# An .npz is a zip of .npy files (the Python tests read it with NumPy).
expect_exit(0 neighbours -i ${WORK}/two.xyz -c 0.5 -o ${WORK}/two.npz -q)
file(READ ${WORK}/two.npz npz HEX LIMIT 4)
expect_match("${npz}" "^504b0304$")
# Bad letters, a bad extension, a missing cutoff: one line, exit 2, nothing written.
expect_exit(2 neighbours -i ${WORK}/two.xyz -c 0.5 -o ${WORK}/bad.npz --quantities ijx)
expect_match("${last_err}" "--quantities 'ijx'")
expect_exit(2 neighbours -i ${WORK}/two.xyz -c 0.5 -o ${WORK}/bad.txt)
expect_match("${last_err}" "must end in .npz or .csv")
expect_exit(2 neighbours -i ${WORK}/two.xyz -o ${WORK}/bad.npz)
if(EXISTS ${WORK}/bad.npz OR EXISTS ${WORK}/bad.txt)
  message(FATAL_ERROR "neighbours left a file behind after an error")
endif()
# -q is accepted by check and bench; short runs print no progress line either way.
expect_exit(0 check -q -m cell-list -f uniform -n 100)
if(NOT last_err STREQUAL "")
  message(FATAL_ERROR "check -q wrote to stderr: ${last_err}")
endif()

message(STATUS "cli: all checks passed")
