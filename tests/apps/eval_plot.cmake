# evio eval --plot: runs scripts/plot_trajectory.py and writes PNG + PDF of each figure.
#   -DEVIO=... -DPYTHON=... -DGT=... -DEST=... -DOUT=...
execute_process(COMMAND ${PYTHON} -c "import numpy, matplotlib" RESULT_VARIABLE have)
if(NOT have EQUAL 0)
  message("SKIP: ${PYTHON} cannot import numpy and matplotlib")
  return()
endif()
file(REMOVE_RECURSE ${OUT})
execute_process(COMMAND ${EVIO} eval ${GT} ${EST} ${EST} --label a --label b --align se3 --plot ${OUT} --python ${PYTHON}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "exit code ${rc}\nstdout:\n${out}\nstderr:\n${err}")
endif()
foreach(f results.json summary.csv summary.tex trajectory_top.png trajectory_top.pdf trajectory_side.png
          trajectory_side.pdf errors_over_time.png errors_over_time.pdf rpe_boxplot.png rpe_boxplot.pdf comparison.png
          comparison.pdf)
  if(NOT EXISTS ${OUT}/${f})
    message(FATAL_ERROR "missing ${OUT}/${f}\nstdout:\n${out}\nstderr:\n${err}")
  endif()
  file(SIZE ${OUT}/${f} size)
  if(size LESS 200)
    message(FATAL_ERROR "${OUT}/${f} has only ${size} bytes")
  endif()
endforeach()
