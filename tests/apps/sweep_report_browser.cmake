# The sweep's HTML report as a browser sees it: writes the report of RESULTS (a results.jsonl; when
# set, copied into OUT first) with `evio sweep --report`, or takes OUT's existing report, and runs
# check_html_report.py on OUT/report/index.html (headless Chromium: no broken image, no script error,
# self-contained, at least MIN_IMAGES images).
#   -DEVIO=... -DPYTHON=... -DCHECK=check_html_report.py -DOUT=DIR [-DRESULTS=file] -DMIN_IMAGES=N
execute_process(COMMAND ${PYTHON} -c "import matplotlib" RESULT_VARIABLE have)
if(NOT have EQUAL 0)
  message("SKIP: ${PYTHON} cannot import matplotlib (the report's plots)")
  return()
endif()
if(RESULTS)
  file(REMOVE_RECURSE ${OUT})
  file(MAKE_DIRECTORY ${OUT})
  configure_file(${RESULTS} ${OUT}/results.jsonl COPYONLY)
  execute_process(COMMAND ${EVIO} sweep --report ${OUT} --python ${PYTHON}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "evio sweep --report: exit code ${rc}\nstdout:\n${out}\nstderr:\n${err}")
  endif()
endif()
execute_process(COMMAND ${PYTHON} ${CHECK} ${OUT}/report/index.html --min-images ${MIN_IMAGES}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(rc EQUAL 77)
  message("SKIP: ${out}")
  return()
endif()
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "check_html_report.py: exit code ${rc}\n${out}\n${err}")
endif()
message("${out}")
